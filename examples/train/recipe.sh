#!/usr/bin/env bash
# A shipped model's training recipe, run from nothing on the canonical sets that
# examples/train/data.sh makes (docs/learning.md, "Training"):
#
#   bash examples/train/recipe.sh tshirt|dress MODEL_DIR [DATA]    # DATA: scratch by default
#
# Each of the three members: pose code, VAE and a first regressor on the set v4c (train all, the
# garment's step-1 settings with 30-frame crops), then its regressor trained again from nothing
# on the larger set, then fine-tuned end to end with the posed collision term and the decoder
# tuned; the members joined.
#   tshirt (version 7, stop 44): tshirt_T30 → tshirt_J0 on v4cs → tshirt_J1 (λ 0.45, 30 epochs)
#                                → tshirt_J (λ 1.5, 60 epochs); no latent smoothing
#   dress (version 9, stop 39):  dress_D30 → dress_L0 on v4css → dress_L (λ 7.7, 30 epochs);
#                                0.1 s latent smoothing
#   (the T-shirt's version 8 and the dress's version 10: the same recipes on the rest sets;
#   the T-shirt's version 9, stop 77: version 8's members, its posed garment smoothed over 1/60 s)
# The run folders go to RUNS/GARMENT_STEP_m{0,1,2} (RUNS: scratch/runs, which the settings'
# init_from name); a step whose run folder holds its result is skipped, so an interrupted run
# goes on where it stopped. Run it from the repository root. DEVICE=cuda trains on a GPU; VERSION
# names the joined model; TRAIN_ARGS is added to every train command (e.g. TRAIN_ARGS="--epochs
# pose=1 --epochs vae=1 --epochs regressor=1" for a quick try). Another training of the same
# recipe, to tell data from chance: SEEDS="3 4 5" (the three members' seeds, over the settings'
# 0 1 2) and RUNS=FOLDER (the run folders' parent, scratch/runs by default). Each fine-tuning step
# starts from the run folder of the step before (--init-from), wherever RUNS puts it. AT_ONCE=1
# runs the three members' first steps (pose code, VAE, first regressor) at once, one thread each,
# each logged in RUNS/GARMENT_STEP_mM.out: on a 2-core machine the VAEs' epochs took 90 s each at
# once against 46 s one after another at two threads (stop 56), 1.5x the throughput; a member
# whose first step fails stops the other two and the recipe. MEMBERS="0" trains only the members
# named (e.g. an ablation of one member, TRAIN_ARGS="--ablation no-collision", against the shipped
# member of the same seed: docs/learning.md, "The paper's Table 1 with the shipped recipe"); the
# members are joined only when all three are named. Beside another job on the same cores, run it
# with OMP_NUM_THREADS=1: at torch's default of a thread a core, a regressor step beside a
# simulation's two workers on 2 cores took 5-33 s an epoch, against 1.7-3.5 s at one thread beside
# those and three VAEs (stop 94; docs/learning.md, "Training").
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

GARMENT=${1:?usage: recipe.sh tshirt|dress MODEL_DIR [DATA]}
MODEL=${2:?usage: recipe.sh tshirt|dress MODEL_DIR [DATA]}
DATA=${3:-scratch}
# STEPS: the regressor's steps after the first, NAME:SETTINGS:PLANES (SETTINGS empty: the run
# folder's own; PLANES: a fine-tuning of the step before, with the posed planes)
case $GARMENT in
    tshirt) FIRST=tshirt_member START=T30 SET=v4cs SMOOTHING=0.0 POSED=0.016666666666666666
        STEPS="J0:tshirt_member: J1:tshirt_v6_step1_member:planes J:tshirt_v6_member:planes" ;;
    dress) FIRST=dress_v9_step1_member START=D30 SET=v4css SMOOTHING=0.1 POSED=0.0
        STEPS="L0:: L:dress_v9_member:planes" ;;
    *) echo "recipe.sh: the garment is tshirt or dress, not '$GARMENT'" >&2; exit 2 ;;
esac
DEVICE=${DEVICE:-cpu}
read -r -a EXTRA <<<"${TRAIN_ARGS:-}"
read -r -a SEED_OF <<<"${SEEDS:-}"
[ ${#SEED_OF[@]} -eq 0 ] || [ ${#SEED_OF[@]} -eq 3 ] || {
    echo "recipe.sh: SEEDS names the three members' seeds, not '$SEEDS'" >&2; exit 2; }
RUNS=${RUNS:-scratch/runs}
read -r -a MEMBER_LIST <<<"${MEMBERS:-0 1 2}"
seen=""
for m in "${MEMBER_LIST[@]}"; do
    [[ $m == [012] && $seen != *$m* ]] || {
        echo "recipe.sh: MEMBERS names members 0, 1 and 2, each once, not '$MEMBERS'" >&2; exit 2; }
    seen+=$m
done
HERE=$(dirname "$0")
PLANES=$DATA/planes_canonical_${GARMENT}_$SET.npz
mkdir -p "$RUNS"

# again FROM TO: a copy of run folder FROM whose regressor is to be trained again
again() {
    rm -rf "$2"
    cp -r "$1" "$2"
    rm -f "$2/checkpoints/regressor.pt" "$2/.done"
}

# seed_of M: member M's seed option (none without SEEDS)
seed_of() {
    [ ${#SEED_OF[@]} -eq 0 ] || echo "--seed ${SEED_OF[$1]}"
}

# first_step M: member M's pose code, VAE and first regressor (train all), unless its run folder
# holds them (model.json, written once all three stages are)
first_step() {
    local run=$RUNS/${GARMENT}_${START}_m$1 seed
    if [ -f "$run/model.json" ]; then
        return
    fi
    read -r -a seed <<<"$(seed_of "$1")"
    usd-garment train all --data "$DATA/canonical_${GARMENT}_v4c.npz" --out "$run" \
        --device "$DEVICE" --config "$HERE/$FIRST$1.json" --resume "${seed[@]}" "${EXTRA[@]}"
}

if [ "${AT_ONCE:-0}" = 1 ]; then
    pids=()
    for m in "${MEMBER_LIST[@]}"; do
        (export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
         first_step $m >"$RUNS/${GARMENT}_${START}_m$m.out" 2>&1) &
        pids+=($!)
    done
    for _ in "${MEMBER_LIST[@]}"; do  # the first member to fail stops the others and the recipe
        wait -n && continue
        for pid in "${pids[@]}"; do
            pkill -TERM -P "$pid" 2>/dev/null || true
            kill "$pid" 2>/dev/null || true
        done
        echo "recipe.sh: a member's first step failed (its log: $RUNS/${GARMENT}_${START}_mM.out);" \
            "the others were stopped (run the recipe again to resume them)" >&2
        exit 1
    done
fi
for m in "${MEMBER_LIST[@]}"; do
    read -r -a seed <<<"$(seed_of "$m")"
    first_step $m
    run=$RUNS/${GARMENT}_${START}_m$m
    for step in $STEPS; do
        IFS=: read -r name settings planes <<<"$step"
        from=$run
        run=$RUNS/${GARMENT}_${name}_m$m
        [ -f "$run/.done" ] && continue
        again "$from" "$run"
        args=()
        [ -n "$settings" ] && args+=(--config "$HERE/$settings$m.json")
        [ -n "$planes" ] && args+=(--init-from "$from" --planes "$PLANES")  # a fine-tuning
        usd-garment train regressor --data "$DATA/canonical_${GARMENT}_$SET.npz" --out "$run" \
            --device "$DEVICE" "${args[@]}" "${seed[@]}" "${EXTRA[@]}"
        touch "$run/.done"
    done
done
# name: the last step's, whose folders hold the members
if [ ${#MEMBER_LIST[@]} -ne 3 ]; then
    echo "recipe.sh: trained member(s) ${MEMBER_LIST[*]} in $RUNS/${GARMENT}_${name}_mM;" \
        "the members are joined only when all three are named" >&2
    exit
fi
usd-garment train combine "$RUNS/${GARMENT}_${name}"_m{0,1,2} --out "$MODEL" \
    --latent-smoothing $SMOOTHING --posed-smoothing $POSED --version "${VERSION:-retrained}"
exit
}
