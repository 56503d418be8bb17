#!/usr/bin/env bash
# The shipped dress model's recipe (version 9, docs/learning.md "Training"), run from nothing on
# the canonical sets that examples/train/data.sh dress makes:
#
#   bash examples/train/dress_v9.sh MODEL_DIR [DATA]    # DATA: scratch by default
#
# Each of the three members: pose code, VAE and a first regressor on v4c (train all), its
# regressor trained again from nothing on v4css, then fine-tuned end to end with the posed
# collision term and the decoder tuned; the members joined with 0.1 s latent smoothing. The run
# folders go to scratch/runs/dress_{D30,L0,L}_m{0,1,2} (examples/train/dress_v9_member*.json
# start from scratch/runs/dress_L0_m*); a stage whose run folder holds its result is skipped,
# so an interrupted run goes on where it stopped. Run it from the repository root. DEVICE=cuda
# trains on a GPU; VERSION names the joined model; TRAIN_ARGS is added to every train command
# (e.g. TRAIN_ARGS="--epochs pose=1 --epochs vae=1 --epochs regressor=1" for a quick try).
set -euo pipefail

MODEL=${1:?usage: dress_v9.sh MODEL_DIR [DATA]}
DATA=${2:-scratch}
DEVICE=${DEVICE:-cpu}
read -r -a EXTRA <<<"${TRAIN_ARGS:-}"
RUNS=scratch/runs
HERE=$(dirname "$0")
PLANES=$DATA/planes_canonical_dress_v4css.npz
mkdir -p "$RUNS"

# again FROM TO: a copy of run folder FROM whose regressor is to be trained again
again() {
    rm -rf "$2"
    cp -r "$1" "$2"
    rm -f "$2/checkpoints/regressor.pt" "$2/.done"
}

for m in 0 1 2; do
    if [ ! -f "$RUNS/dress_D30_m$m/model.json" ]; then  # written once all three stages are
        usd-garment train all --data "$DATA/canonical_dress_v4c.npz" --out "$RUNS/dress_D30_m$m" \
            --device "$DEVICE" --config "$HERE/dress_v9_step1_member$m.json" --resume "${EXTRA[@]}"
    fi
    if [ ! -f "$RUNS/dress_L0_m$m/.done" ]; then
        again "$RUNS/dress_D30_m$m" "$RUNS/dress_L0_m$m"
        usd-garment train regressor --data "$DATA/canonical_dress_v4css.npz" \
            --out "$RUNS/dress_L0_m$m" --device "$DEVICE" "${EXTRA[@]}"
        touch "$RUNS/dress_L0_m$m/.done"
    fi
    if [ ! -f "$RUNS/dress_L_m$m/.done" ]; then
        again "$RUNS/dress_L0_m$m" "$RUNS/dress_L_m$m"
        usd-garment train regressor --data "$DATA/canonical_dress_v4css.npz" \
            --out "$RUNS/dress_L_m$m" --device "$DEVICE" \
            --config "$HERE/dress_v9_member$m.json" --planes "$PLANES" "${EXTRA[@]}"
        touch "$RUNS/dress_L_m$m/.done"
    fi
done
usd-garment train combine "$RUNS"/dress_L_m{0,1,2} --out "$MODEL" --latent-smoothing 0.1 \
    --version "${VERSION:-retrained}"
