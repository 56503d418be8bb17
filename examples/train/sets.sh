# Sourced by data.sh, data_amc.sh, data_arms.sh and data_cap35.sh once GARMENT, OUT and COLLARS
# are set: the steps they repeat, with the training sets' common settings.

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
