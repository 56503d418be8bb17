#!/usr/bin/env bash
# Four CMU captures in ASF/AMC of two subjects no model trains on (examples/mocap/README.md,
# "Four more held-out captures"): 01_01 forward jumps, 01_08 climb, sit, dangle legs, rock back,
# 03_01 and 03_03 walks on uneven terrain, at 30 fps (03_03's first 20 s).
#
#   bash examples/heldout_amc.sh [OUT_DIR]   # scratch/heldout_amc
#
# Writes, for each clip X, OUT_DIR/cap_X.usdc (imported as `import-bvh` does by default: the
# shoulders opened where an arm comes within 5 mm of the trunk) and OUT_DIR/arms_X.usdc (the arms
# as captured, --arm-clearance 0); about 40 s. No simulation: 01_08 climbs and sits on equipment
# the capture does not hold (the other three simulate: `usd-garment dataset make --capture
# OUT_DIR/cap_X.usdc:test ...`, docs/judge.md, "Four more held-out captures"). Bench with
#   usd-garment bench OUT_DIR/*.usdc --method learned --method learned+preimage --method lbs \
#       --method lbs+postprocess --lod high --workers 2 -o OUT
set -euo pipefail
OUT=${1:-scratch/heldout_amc}
mkdir -p "$OUT"
for clip in 01_01:2751 01_08:2610 03_01:432 03_03:2400; do  # name:frames used, at 120 fps
    name=${clip%:*}
    end=${clip#*:}
    amc=examples/mocap/asf/$name.amc.xz
    usd-garment import-bvh "$amc" -o "$OUT/cap_$name.usdc" --fps 30 --frames "0:$end"
    usd-garment import-bvh "$amc" -o "$OUT/arms_$name.usdc" --fps 30 --frames "0:$end" \
        --arm-clearance 0
done
