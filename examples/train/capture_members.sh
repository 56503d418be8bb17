#!/usr/bin/env bash
# The T-shirt's version 10 (stop 87; docs/learning.md, "The shipped T-shirt model, version 10"):
# the three members of a model (version 9) with two members trained with 35 more real captures,
# joined as five and stored as int8 so that they fit in 12 MB.
#
#   bash examples/train/capture_members.sh MEMBERS_MODEL OUT_MODEL [DATA] [CAPTURES]
#
# MEMBERS_MODEL: the model whose members are kept (version 9: `git archive 316d832
# usd_garment/data/models/tshirt | tar -x -C DIR`); DATA: examples/train/data.sh's OUT
# (scratch/rest by default), whose canonical_tshirt_v4c.npz trains the capture members' pose
# code and VAE; CAPTURES: examples/train/data_cap35.sh's OUT (scratch/cap35 by default), whose
# canonical_tshirt_v4c.npz (DATA's v4c and the 35 captures) trains their regressors.
# The capture members (stop 81's CAP chain, seeds 0 and 1 sharing one pose code and VAE):
#   base        train all on DATA's v4c (tshirt_member0.json: pose code, VAE, a first regressor)
#   J0 (seed N) the regressor again from nothing on CAPTURES' v4c (tshirt_member0.json)
#   J1 (seed N) fine-tuned under the posed planes, λ 0.45, 30 epochs (tshirt_v6_step1_member0.json)
#   J  (seed N) fine-tuned again, λ 1.5, 60 epochs (tshirt_v6_member0.json)
# Run folders go to RUNS/cap_* (RUNS: scratch/runs_cap); a step whose folder holds its result is
# skipped, so an interrupted run goes on where it stopped. BASE names a run folder to use as the
# base instead of training one into RUNS/cap_base: the same command's result (`train all` on
# DATA's v4c with tshirt_member0.json and TRAIN_ARGS), such as recipe.sh's member 0's first step
# (RUNS/tshirt_T30_m0), which table1.sh passes rather than train that twice. Stop 87 on 2 cores:
# base 2,131 s (the VAE slowed by a projection beside it for its first epochs), the posed planes
# of the 101 sequences about 11 minutes (made once, in seed 0's J1), each seed's three regressor
# steps 5-6 minutes. DEVICE=cuda trains on a GPU; TRAIN_ARGS is added to every train command, as in
# recipe.sh (e.g. TRAIN_ARGS="--ablation no-collision": examples/train/table1.sh); VERSION names
# the joined model (10 by default).
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

MEMBERS=${1:?usage: capture_members.sh MEMBERS_MODEL OUT_MODEL [DATA] [CAPTURES]}
MODEL=${2:?usage: capture_members.sh MEMBERS_MODEL OUT_MODEL [DATA] [CAPTURES]}
DATA=${3:-scratch/rest}
CAPTURES=${4:-scratch/cap35}
RUNS=${RUNS:-scratch/runs_cap}
DEVICE=${DEVICE:-cpu}
read -r -a EXTRA <<<"${TRAIN_ARGS:-}"
HERE=$(dirname "$0")
SET=$CAPTURES/canonical_tshirt_v4c.npz
PLANES=$CAPTURES/planes_canonical_tshirt_v4c.npz
mkdir -p "$RUNS"

BASE=${BASE:-}
if [ -n "$BASE" ]; then
    [ -f "$BASE/model.json" ] || {
        echo "capture_members.sh: BASE '$BASE' holds no trained model (model.json)" >&2; exit 2; }
else
    BASE=$RUNS/cap_base
    if [ ! -f "$BASE/model.json" ]; then
        usd-garment train all --data "$DATA/canonical_tshirt_v4c.npz" --out "$BASE" \
            --device "$DEVICE" --config "$HERE/tshirt_member0.json" --resume "${EXTRA[@]}"
    fi
fi
for seed in 0 1; do
    from=$BASE
    for step in J0:tshirt_member0: J1:tshirt_v6_step1_member0:planes J:tshirt_v6_member0:planes; do
        IFS=: read -r name settings planes <<<"$step"
        run=$RUNS/cap_${name}_s$seed
        if [ ! -f "$run/.done" ]; then
            rm -rf "$run"
            cp -r "$from" "$run"
            rm -f "$run/checkpoints/regressor.pt" "$run/.done"
            args=(--config "$HERE/$settings.json" --seed "$seed")
            [ -n "$planes" ] && args+=(--init-from "$from" --planes "$PLANES")
            usd-garment train regressor --data "$SET" --out "$run" --device "$DEVICE" "${args[@]}" \
                "${EXTRA[@]}"
            touch "$run/.done"
        fi
        from=$run
    done
done
kept=()
count=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))['members']))" \
    "$MEMBERS/model.json")
for ((i = 0; i < count; i++)); do
    usd-garment train member "$MEMBERS" --index "$i" --out "$RUNS/kept_m$i"
    kept+=("$RUNS/kept_m$i")
done
usd-garment train combine "${kept[@]}" "$RUNS/cap_J_s0" "$RUNS/cap_J_s1" --out "$MODEL" \
    --version "${VERSION:-10}" --posed-smoothing 0.016666666666666666 --weights int8
exit
}
