# Sourced by data.sh, data_amc.sh, data_arms.sh and data_cap35.sh: the steps they repeat, with the
# training sets' common settings. The functions read GARMENT, OUT, COLLARS (and BASE and LAST, set
# by garment_args.sh) when they are called.

# FOLDER: the captures' body layers go in FOLDER (CAPTURES, made here); the array captures starts
# empty
captures_in() {
    CAPTURES=$1
    mkdir -p "$CAPTURES"
    captures=()
}

# SOURCE USD [IMPORT-BVH ARGS...]: import the capture SOURCE as the body layer USD (kept where a
# run before made it) and add it to the array captures as a training capture
add_capture() {
    local source=$1 usd=$2
    shift 2
    [ -f "$usd" ] || usd-garment import-bvh "$source" -o "$usd" --collars "$COLLARS" "$@"
    captures+=(--capture "$usd:train")
}

set_of() {  # NAME ARGS...: make (or finish) the set OUT/dataset_GARMENT_NAME
    local name=$1
    shift
    usd-garment dataset make --garment "$GARMENT" --frames 90 --workers 2 --resume \
        --collars "$COLLARS" "$@" -o "$OUT/dataset_${GARMENT}_$name"
}

project_onto() {  # FILE NAME: add the set NAME's layers that FILE lacks
    usd-garment project --manifest "$OUT/dataset_${GARMENT}_$2" -o "$1" --workers 2 --update
}

# NAME: add the set NAME to OUT's copies of BASE's v4c and LAST (set by garment_args.sh)
onto_base_copies() {
    local set=$1 name file
    for name in v4c $LAST; do
        file=$OUT/canonical_${GARMENT}_$name.npz
        [ -f "$file" ] || cp "$BASE/canonical_${GARMENT}_$name.npz" "$file"
        project_onto "$file" "$set"
    done
}

# NAME: make the set NAME of the array captures (train only, one body shape, seed 3: as cmu4) and
# add it to OUT's copies of BASE's v4c and LAST
captures_onto_base() {
    set_of "$1" --motions 0 --shapes 1 --seed 3 "${captures[@]}"
    onto_base_copies "$1"
}
