#!/usr/bin/env bash
# Thirty-five more real captures for a garment's training: CMU subjects 05 (dance), 06
# (basketball) and 08 (walks) of examples/mocap/cmu35/ (docs/learning.md, "More simulated
# captures in the regressor's training"), simulated as the set cap35 (train only, one body
# shape, as cmu4), and projected onto copies of the canonical sets of BASE
# (examples/train/data.sh's OUT), so that the recipe trains on them with DATA=OUT:
#
#   bash examples/train/data_cap35.sh tshirt|dress OUT [BASE]    # BASE: scratch/rest by default
#
#   OUT/canonical_GARMENT_v4c.npz     BASE's v4c + cap35 (stop 81's v4c058 for the T-shirt)
#   OUT/canonical_tshirt_v4cs.npz     BASE's v4cs + cap35 (the T-shirt's regressors)
#   OUT/canonical_dress_v4css.npz     BASE's v4css + cap35 (the dress's regressors)
#
# Each capture whole but for its T-pose (import-bvh leaves it out): 5,321 frames at 30 fps
# (05_06 does not simulate, so the set holds 5,099; stop 81: 42 min of simulation for the
# T-shirt on 2 cores). Run it again to finish what an interrupted run left (the set resumes; a
# projection adds only the layers a file lacks). COLLARS as data.sh's (rest by default).
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

source "$(dirname "$0")/garment_args.sh" "$@"  # GARMENT OUT BASE LAST
COLLARS=${COLLARS:-rest}
source "$(dirname "$0")/sets.sh"  # captures_in, add_capture, captures_onto_base
captures_in "$OUT/mocap_cap35/usd"

for bvh in "$(dirname "$0")"/../mocap/cmu35/cmu_*.bvh.xz; do
    add_capture "$bvh" "$CAPTURES/$(basename "$bvh" .bvh.xz).usdc"
done
captures_onto_base cap35
exit
}
