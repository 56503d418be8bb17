#!/usr/bin/env bash
# The AMASS-style walk that the chart runs of docs/judge.md bench (collisions only, no
# simulation): a procedural walk of 480 frames at 120 fps on body shape β₁..β₄ = -0.793, 0.241,
# -1.896, 1.396 (drawn from N(0, 1) with seed 2026), the arms hanging at the sides, written as a
# user would bring it: exported to a Z-up AMASS .npz at 120 fps, then imported.
#
#   bash examples/heldout_walk.sh [OUT_DIR]    # OUT_DIR: scratch/heldout; a few seconds
#
# Writes OUT_DIR/amass_walk120.usdc (the body layer benched), with the .usda it was exported from
# and the .npz beside it.
set -euo pipefail
OUT=${1:-scratch/heldout}
mkdir -p "$OUT"
usd-garment motion make walk --frames 480 --fps 120 --seed 11 \
    --betas=-0.793,0.241,-1.896,1.396 -o "$OUT/amass_walk120_source.usda"
usd-garment export-amass "$OUT/amass_walk120_source.usda" -o "$OUT/amass_walk120.npz"
usd-garment import-amass "$OUT/amass_walk120.npz" -o "$OUT/amass_walk120.usdc"
