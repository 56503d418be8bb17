#!/usr/bin/env bash
# The training data of a shipped model (the T-shirt's version 8, the dress's version 10; with
# COLLARS=aimed, below, version 7's and version 9's), made from nothing with the current simulator: the four extra CMU
# captures imported, the simulated sets, and the canonical sets its training reads
# (docs/learning.md, "The dress's data in one command").
#
#   bash examples/train/data.sh tshirt|dress [OUT]    # OUT: scratch by default
#
# Run it again to finish what an interrupted run left: each set resumes, each projection adds
# only the layers it lacks. Needs the three CMU clips of ../shared/mocap beside the project
# (MOCAP=DIR to read them elsewhere). On a 2-core machine (stop 41), the dress: 1 h 42 min of
# simulation (v4 28 min, v4x 17, cmu4 13, v5s 16, v6s 28), then about 12 minutes of projection.
# The T-shirt's sets are larger (three body shapes a motion, the dress's two): v4 51 min, v4x 34
# (stop 42), cmu4 16 and v5s 18 (stop 43): about 2 h of simulation, then 12 minutes of
# projection. Those times are from before stop 58, whose workers run one torch thread each:
# the T-shirt's v5s then took 14.5 minutes, about 2.5 times as fast as before on the same
# machine (docs/simulation.md, "Training data").
#
# Each set can be held to its newest committed manifest (rest collars: T-shirt *_rest_stop55,
# dress *_rest_stop59; aimed: dress *_stop41, v5s *_stop40; T-shirt v4 and v4x *_stop42, cmu4 and v5s *_stop43):
# usd-garment dataset compare docs/datasets/GARMENT_NAME_..._manifest.json OUT/dataset_GARMENT_NAME
#
# COLLARS (rest by default, as `import-bvh`) is how the captures are imported and simulated:
# rest, the collars from the body's rest collars (no shrug: docs/mocap.md), made the T-shirt's
# version 8 data (stops 55-58) and the dress's version 10 data (stop 59); COLLARS=aimed the
# T-shirt's version 7 and the dress's version 9 data. Give each its own OUT: imports already in OUT are kept.
#
#   canonical_GARMENT_v4c.npz      v4 + v4x + cmu4: the members' VAEs and pose codes
#   canonical_tshirt_v4cs.npz      v4c + v5s: the T-shirt's regressors
#   canonical_dress_v4css.npz      v4c + v5s + v6s: the dress's regressors
set -euo pipefail
# One compound command, read whole before it runs: editing this file during a run (hours) does
# not change the run (stop 42's data run broke on an edit of the header: bash reads a script as it
# goes).
{

GARMENT=${1:?usage: data.sh tshirt|dress [OUT]}
OUT=${2:-scratch}
case $GARMENT in
    tshirt) SHAPES=3 NEW_SHAPES="v5s" LAST=v4cs ;;
    dress) SHAPES=2 NEW_SHAPES="v5s v6s" LAST=v4css ;;
    *) echo "data.sh: the garment is tshirt or dress, not '$GARMENT'" >&2; exit 2 ;;
esac
MOCAP=${MOCAP:-../shared/mocap}
COLLARS=${COLLARS:-rest}
EXTRA="$(dirname "$0")/../mocap"
CAPTURES=$OUT/mocap_extra/usd
mkdir -p "$CAPTURES"

# The four captures of subjects 13 and 14, frame 0 (the conversion's T-pose) left out.
for clip in 13_26:1:3029:cmu_13_26 13_29:1:2400:cmu_13_29_frames0000-2399 \
    14_04:1:760:cmu_14_04 13_39:1:352:cmu_13_39; do
    IFS=: read -r name first last usd <<<"$clip"
    if [ ! -f "$CAPTURES/$usd.usdc" ]; then
        usd-garment import-bvh "$EXTRA/cmu_$name.bvh.xz" -o "$CAPTURES/$usd.usdc" \
            --frames "$first:$last" --collars "$COLLARS"
    fi
done

source "$(dirname "$0")/sets.sh"  # set_of NAME ARGS..., project_onto FILE NAME
set_of v4 --motions 10 --shapes $SHAPES --seed 0 \
    --capture "$MOCAP/cmu_131_01.bvh:train" --capture "$MOCAP/cmu_131_02.bvh:validation" \
    --capture "$MOCAP/cmu_131_03.bvh:test"
set_of v4x --motions 10 --shapes $SHAPES --seed 1 --train-only
set_of cmu4 --motions 0 --shapes 1 --seed 3 \
    --capture "$CAPTURES/cmu_13_26.usdc:train" \
    --capture "$CAPTURES/cmu_13_29_frames0000-2399.usdc:train" \
    --capture "$CAPTURES/cmu_14_04.usdc:train" --capture "$CAPTURES/cmu_13_39.usdc:train"
for name in $NEW_SHAPES; do  # twenty motions, each on its own shape drawn at ±2 σ; v5s: seed 5
    set_of "$name" --motions 20 --shapes 1 --shape-per-motion --shape-sigma 2 \
        --seed "${name//[!0-9]/}" --train-only
done

FIRST=$OUT/canonical_${GARMENT}_v4c.npz
FINAL=$OUT/canonical_${GARMENT}_$LAST.npz
for name in v4 v4x cmu4; do
    project_onto "$FIRST" $name
done
[ -f "$FINAL" ] || cp "$FIRST" "$FINAL"
for name in $NEW_SHAPES; do
    project_onto "$FINAL" "$name"
done
exit
}
