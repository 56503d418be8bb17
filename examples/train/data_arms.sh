#!/usr/bin/env bash
# The training captures with the arms as captured (docs/learning.md, "The T-shirt trained with
# the arms as captured"): cmu4's four captures and CMU 131_01 imported with `--arm-clearance 0`
# (the upper arms pass into the trunk, as raw captures and AMASS hold them; data.sh's imports open
# the shoulders), simulated as the set arms5 (the first body shape, β = 0, cmu4's) and cmu4's
# four again as arms4b on seed 4's two shapes: its first is β = 0 again, so those four sequences
# are arms5's to the bit (the regressor set of stop 64's candidate ARMS3 holds them twice), its
# second new (β₁..β₄ -0.39, 0.95, 0.59, -1.00). Each set projected onto a copy of BASE's
# regressor set:
#
#   bash examples/train/data_arms.sh tshirt|dress OUT [BASE]    # BASE: scratch/rest by default
#
#   OUT/canonical_GARMENT_LAST_arms.npz     BASE's LAST + arms5 (stop 64's candidate ARMS)
#   OUT/canonical_GARMENT_LAST_arms3.npz    ... + arms4b (stop 64's candidate ARMS3)
#
# LAST: v4cs for the T-shirt, v4css for the dress (the dress's sets never made so far). Run it
# again to finish what an interrupted run left. On 2 cores (stop 64, T-shirt, beside training
# runs): arms5 11 minutes (131_01 fails at motion frame 63: 4 of 5 sequences, 1,635 frames),
# arms4b 18 minutes (13_26 on the second shape fails at frame 465: 7 of 8, 2,513 frames), the
# projections 1 and 2.6 minutes.
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

source "$(dirname "$0")/garment_args.sh" "$@"  # GARMENT OUT BASE LAST
COLLARS=rest  # the imports' and the sets'
MOCAP=${MOCAP:-../shared/mocap}
EXTRA="$(dirname "$0")/../mocap"
source "$(dirname "$0")/sets.sh"  # captures_in, add_capture, set_of, project_onto
captures_in "$OUT/arms/usd"

# data.sh's clips, frames and names of cmu4, then 131_01 whole
for clip in 13_26:1:3029:cmu_13_26 13_29:1:2400:cmu_13_29_frames0000-2399 \
    14_04:1:760:cmu_14_04 13_39:1:352:cmu_13_39; do
    IFS=: read -r name first last file <<<"$clip"
    add_capture "$EXTRA/cmu_$name.bvh.xz" "$CAPTURES/$file.usdc" --frames "$first:$last" \
        --arm-clearance 0
done
cmu4=("${captures[@]}")
add_capture "$MOCAP/cmu_131_01.bvh" "$CAPTURES/cmu_131_01.usdc" --arm-clearance 0

set_of arms5 --motions 0 --shapes 1 --seed 3 "${captures[@]}"
set_of arms4b --motions 0 --shapes 2 --capture-shapes 2 --seed 4 "${cmu4[@]}"

FIRST=$OUT/canonical_${GARMENT}_${LAST}_arms.npz
[ -f "$FIRST" ] || cp "$BASE/canonical_${GARMENT}_$LAST.npz" "$FIRST"
project_onto "$FIRST" arms5
SECOND=$OUT/canonical_${GARMENT}_${LAST}_arms3.npz
[ -f "$SECOND" ] || cp "$FIRST" "$SECOND"
project_onto "$SECOND" arms4b
exit
}
