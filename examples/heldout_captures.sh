#!/usr/bin/env bash
# Four CMU captures that no shipped model trains on and no setting was tuned on
# (examples/mocap/README.md, "Four captures no model has seen"): walks 02_01 and 07_01, run
# 09_01 and the 18 s clip 14_27, each at 30 fps without the file's first frame (a T-pose).
#
#   bash examples/heldout_captures.sh [OUT_DIR] [GARMENT] [COLLARS]   # scratch/captures, tshirt, rest
#
# Writes, for each clip X, OUT_DIR/cap_X.usdc (imported as `import-bvh` does by default: the
# shoulders opened where an arm comes within 5 mm of the trunk) and OUT_DIR/arms_X.usdc (the
# arms as captured, --arm-clearance 0), both with `import-bvh --collars COLLARS` (rest, the
# default since stop 59, or aimed: docs/mocap.md), then simulates GARMENT on the cap_ layers into
# OUT_DIR/dataset_GARMENT, all four in its test split (740 frames; the T-shirt about 25 min
# on 2 cores; resumes when run again). Bench them with, e.g.,
#   usd-garment bench --manifest OUT_DIR/dataset_tshirt --split test --lod high -o OUT
#   usd-garment bench OUT_DIR/arms_*.usdc --lod high -o OUT
set -euo pipefail
OUT=${1:-scratch/captures}
GARMENT=${2:-tshirt}
COLLARS=${3:-rest}
mkdir -p "$OUT"
captures=()
for clip in 14_27:2153 02_01:344 07_01:317 09_01:149; do  # name:frames in the file
    name=${clip%:*}
    end=${clip#*:}
    bvh=examples/mocap/cmu_$name.bvh.xz
    usd-garment import-bvh "$bvh" -o "$OUT/cap_$name.usdc" --fps 30 --frames "1:$end" \
        --collars "$COLLARS"
    usd-garment import-bvh "$bvh" -o "$OUT/arms_$name.usdc" --fps 30 --frames "1:$end" \
        --arm-clearance 0 --collars "$COLLARS"
    captures+=(--capture "$OUT/cap_$name.usdc:test")
done
usd-garment dataset make --garment "$GARMENT" --motions 0 --shapes 1 --seed 0 --workers 2 \
    --resume "${captures[@]}" -o "$OUT/dataset_$GARMENT"
