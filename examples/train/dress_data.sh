#!/usr/bin/env bash
# The training data of the shipped dress model (version 9's recipe), made from nothing with the
# current simulator: the four extra CMU captures imported, five simulated sets, and the two
# canonical sets its training reads (docs/learning.md, "The dress's data in one command").
#
#   bash examples/train/dress_data.sh [OUT]    # OUT: scratch by default
#
# Run it again to finish what an interrupted run left: each set resumes, each projection adds
# only the layers it lacks. Needs the three CMU clips of ../shared/mocap beside the project
# (MOCAP=DIR to read them elsewhere). On a 2-core machine (stop 41): 1 h 42 min of simulation
# (v4 28 min, v4x 17, cmu4 13, v5s 16, v6s 28), then about 12 minutes of projection.
#
#   canonical_dress_v4c.npz    v4 + v4x + cmu4: the members' VAEs and pose codes
#   canonical_dress_v4css.npz  v4c + v5s + v6s: their regressors
set -euo pipefail

OUT=${1:-scratch}
MOCAP=${MOCAP:-../shared/mocap}
EXTRA="$(dirname "$0")/../mocap"
CAPTURES=$OUT/mocap_extra/usd
mkdir -p "$CAPTURES"

# The four captures of subjects 13 and 14, frame 0 (the conversion's T-pose) left out.
for clip in 13_26:1:3029:cmu_13_26 13_29:1:2400:cmu_13_29_frames0000-2399 \
    14_04:1:760:cmu_14_04 13_39:1:352:cmu_13_39; do
    IFS=: read -r name first last usd <<<"$clip"
    if [ ! -f "$CAPTURES/$usd.usdc" ]; then
        usd-garment import-bvh "$EXTRA/cmu_$name.bvh.xz" -o "$CAPTURES/$usd.usdc" \
            --frames "$first:$last"
    fi
done

set_of() {  # NAME ARGS...: make (or finish) the dress set OUT/dataset_dress_NAME
    local name=$1
    shift
    usd-garment dataset make --garment dress --frames 90 --workers 2 --resume "$@" \
        -o "$OUT/dataset_dress_$name"
}
set_of v4 --motions 10 --shapes 2 --seed 0 \
    --capture "$MOCAP/cmu_131_01.bvh:train" --capture "$MOCAP/cmu_131_02.bvh:validation" \
    --capture "$MOCAP/cmu_131_03.bvh:test"
set_of v4x --motions 10 --shapes 2 --seed 1 --train-only
set_of cmu4 --motions 0 --shapes 1 --seed 3 \
    --capture "$CAPTURES/cmu_13_26.usdc:train" \
    --capture "$CAPTURES/cmu_13_29_frames0000-2399.usdc:train" \
    --capture "$CAPTURES/cmu_14_04.usdc:train" --capture "$CAPTURES/cmu_13_39.usdc:train"
set_of v5s --motions 20 --shapes 1 --shape-per-motion --shape-sigma 2 --seed 5 --train-only
set_of v6s --motions 20 --shapes 1 --shape-per-motion --shape-sigma 2 --seed 6 --train-only

project_onto() {  # FILE NAME: add the set's layers that FILE lacks
    usd-garment project --manifest "$OUT/dataset_dress_$2" -o "$1" --workers 2 --update
}
for name in v4 v4x cmu4; do
    project_onto "$OUT/canonical_dress_v4c.npz" $name
done
[ -f "$OUT/canonical_dress_v4css.npz" ] || cp "$OUT/canonical_dress_v4c.npz" "$OUT/canonical_dress_v4css.npz"
for name in v5s v6s; do
    project_onto "$OUT/canonical_dress_v4css.npz" $name
done
