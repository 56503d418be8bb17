#!/usr/bin/env bash
# More real motion for a garment's training: four captures of CMU subject 02 in the database's
# own ASF/AMC format (examples/mocap/asf/: punch/strike, bend over and lift an arm, swordplay,
# wash self; docs/learning.md, "Real captures from ASF/AMC in the T-shirt's training"), simulated
# as the set amc4 (train only, one body shape, as cmu4), and projected onto copies of the
# canonical sets of BASE (examples/train/data.sh's OUT), so that the recipe trains on them with
# DATA=OUT:
#
#   bash examples/train/data_amc.sh tshirt|dress OUT [BASE]    # BASE: scratch/rest by default
#
#   OUT/canonical_GARMENT_v4c.npz     BASE's v4c + amc4 (the members' VAEs and pose codes)
#   OUT/canonical_tshirt_v4cs.npz     BASE's v4cs + amc4 (the T-shirt's regressors)
#   OUT/canonical_dress_v4css.npz     BASE's v4css + amc4 (the dress's regressors)
#
# Run it again to finish what an interrupted run left (the set resumes; a projection adds only
# the layers a file lacks). COLLARS as data.sh's (rest by default). 1,846 frames at 30 fps.
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

source "$(dirname "$0")/garment_args.sh" "$@"  # GARMENT OUT BASE LAST
COLLARS=${COLLARS:-rest}
source "$(dirname "$0")/sets.sh"  # captures_in, add_capture, captures_onto_base
captures_in "$OUT/mocap_amc/usd"

# clip:first:end (frames of the file at 120 fps, end exclusive): the whole of 02_05 and 02_10,
# the first 12 s of 02_06 and 02_07
ASF="$(dirname "$0")/../mocap/asf"
for clip in 02_05:0:1854 02_06:0:1440 02_07:0:1440 02_10:0:2645; do
    IFS=: read -r name first end <<<"$clip"
    add_capture "$ASF/$name.amc.xz" "$CAPTURES/cmu_${name}.usdc" --frames "$first:$end"
done
captures_onto_base amc4
exit
}
