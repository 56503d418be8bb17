#!/usr/bin/env bash
# A candidate model judged as the shipped models were (docs/learning.md, the rules of stops
# 36-43): networks alone at the high level of detail, in the same bench runs as the shipped model
# of the garment (benched as `learned`).
#
#   bash examples/train/judge.sh tshirt|dress CANDIDATE_DIR FIRST_SEED OUT [DATA]
#
# Gate 1: the validation split of DATA/dataset_GARMENT_v4 (DATA: scratch by default), against
#   its simulations.
# Gate 2: a fresh new-shapes set in OUT/shapes_test, made here where it is not there yet: eight
#   procedural motions of 150 frames, one of each kind below, seeds FIRST_SEED to FIRST_SEED+7,
#   each on its own random body shape, the garment simulated on each (two at a time). Make it
#   after the candidate is trained, with seeds no earlier set used, and bench nothing on it
#   before: a set is fresh once.
# Reported, not for deciding: the test split; CMU 131_02 with the arms as captured (collisions
#   only, lbs beside); each of the three members of both models alone on v4's two held-out
#   captures (c01_s0: validation, c02_s0: test).
# Each bench writes its report folder OUT/NAME (report.json, chart.png, ...) and its log
# OUT/NAME.log. On a 2-core machine, about an hour for the T-shirt, most of it the fresh set's
# simulations. Needs ../shared/mocap beside the project (MOCAP=DIR to read it elsewhere);
# LABEL names the candidate in the reports (default: its folder's name); COLLARS (rest by
# default) imports CMU 131_02 as `import-bvh --collars` does, as DATA's sets were made
# (data.sh's COLLARS).
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

GARMENT=${1:?usage: judge.sh tshirt|dress CANDIDATE_DIR FIRST_SEED OUT [DATA]}
CANDIDATE=${2:?usage: judge.sh tshirt|dress CANDIDATE_DIR FIRST_SEED OUT [DATA]}
FIRST_SEED=${3:?usage: judge.sh tshirt|dress CANDIDATE_DIR FIRST_SEED OUT [DATA]}
OUT=${4:?usage: judge.sh tshirt|dress CANDIDATE_DIR FIRST_SEED OUT [DATA]}
DATA=${5:-scratch}
case $GARMENT in
    tshirt | dress) ;;
    *) echo "judge.sh: the garment is tshirt or dress, not '$GARMENT'" >&2; exit 2 ;;
esac
MOCAP=${MOCAP:-../shared/mocap}
LABEL=${LABEL:-$(basename "$CANDIDATE")}
COLLARS=${COLLARS:-rest}
SET=$DATA/dataset_${GARMENT}_v4
FRESH=$OUT/shapes_test
KINDS=(walk run jumping_jacks arm_swing arm_raise torso_twist torso_bend squat)
mkdir -p "$FRESH"

bench() {  # NAME ARGS...: usd-garment bench ARGS into OUT/NAME, logged in OUT/NAME.log
    local name=$1 start=$SECONDS
    shift
    if usd-garment bench "$@" --garment "$GARMENT" --lod high -o "$OUT/$name" \
        >"$OUT/$name.log" 2>&1; then
        echo "$name: $((SECONDS - start)) s"
    else
        echo "$name: the bench failed ($OUT/$name.log)"
    fi
}

# gate 1
bench val --manifest "$SET" --split validation --method learned --model "$LABEL=$CANDIDATE" \
    --workers 2

# gate 2: the fresh set (each motion and simulation made once), then its bench
fresh_one() {  # KIND SEED
    local body=$FRESH/$1_$2.usdc garment=$FRESH/$1_$2_$GARMENT.usdc
    [ -f "$body" ] || usd-garment motion make "$1" --frames 150 --seed "$2" --betas random \
        -o "$body" >"$FRESH/$1_$2.log" 2>&1
    [ -f "$garment" ] || usd-garment simulate "$body" --garment "$GARMENT" -o "$garment" \
        >>"$FRESH/$1_$2.log" 2>&1 || echo "$1_$2: the simulation failed ($FRESH/$1_$2.log)"
}
export -f fresh_one
export FRESH GARMENT
start=$SECONDS
for k in "${!KINDS[@]}"; do
    echo "${KINDS[$k]} $((FIRST_SEED + k))"
done | OMP_NUM_THREADS=1 xargs -P 2 -L 1 bash -c 'fresh_one "$0" "$1"'  # 1 thread each: 2 cores
echo "fresh set: $((SECONDS - start)) s"
inputs=()
for k in "${!KINDS[@]}"; do
    name=${KINDS[$k]}_$((FIRST_SEED + k))
    if [ -f "$FRESH/${name}_$GARMENT.usdc" ]; then
        inputs+=("$FRESH/$name.usdc" --reference "$FRESH/${name}_$GARMENT.usdc")
    fi
done
bench shapes "${inputs[@]}" --method learned --model "$LABEL=$CANDIDATE" --workers 2

# reported
bench test --manifest "$SET" --split test --method learned --model "$LABEL=$CANDIDATE" \
    --workers 2
ARMS=$OUT/cmu_131_02_arms.usdc
[ -f "$ARMS" ] || usd-garment import-bvh "$MOCAP/cmu_131_02.bvh" -o "$ARMS" --fps 30 \
    --arm-clearance 0 --collars "$COLLARS"
bench arms "$ARMS" --method learned --method lbs --model "$LABEL=$CANDIDATE" --workers 2
members=()
for m in 0 1 2; do
    usd-garment train member "usd_garment/data/models/$GARMENT" --index $m \
        --out "$OUT/members/shipped_m$m"
    usd-garment train member "$CANDIDATE" --index $m --out "$OUT/members/${LABEL}_m$m"
    members+=(--model "shipped_m$m=$OUT/members/shipped_m$m"
        --model "${LABEL}_m$m=$OUT/members/${LABEL}_m$m")
done
bench members "$SET/c01_s0_body.usdc" "$SET/c02_s0_body.usdc" \
    --reference "$SET/c01_s0_$GARMENT.usdc" --reference "$SET/c02_s0_$GARMENT.usdc" \
    --method learned --model "$LABEL=$CANDIDATE" "${members[@]}" --workers 1
exit
}
