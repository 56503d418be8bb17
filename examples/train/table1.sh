#!/usr/bin/env bash
# The paper's Table 1 for a shipped model (docs/learning.md, "The paper's Table 1 with the
# shipped recipe"): each of the paper's two VAE ablations trained with the shipped model's whole
# recipe, the ablation on every VAE and everything else the same, then one bench of the shipped
# model (`learned`), the ablations, `lbs` and `lbs+postprocess`, and the shipped model's default
# method (`learned+preimage`, which the issue's 0.05 % is judged on) in the same run.
#
#   bash examples/train/table1.sh tshirt|dress OUT [DATA] [CAPTURES]
#
# The recipes: the dress (version 10) is recipe.sh's three members; the T-shirt (version 10) is
# recipe.sh's three members (its version 9) and capture_members.sh's two, joined as five in int8.
# The capture members' base is recipe.sh's member 0's first step (BASE): capture_members.sh's own
# base is the same command (`train all` on DATA's v4c, tshirt_member0.json), not trained twice.
# DATA: data.sh's OUT (scratch/rest by default: the rest collars the shipped models trained on);
# CAPTURES: data_cap35.sh's OUT (scratch/cap35 by default; the T-shirt's capture members only).
# Each ablation's model goes to OUT/GARMENT_ABLATION, its run folders to OUT/runs/ABLATION; a
# step already done is skipped, so an interrupted run goes on where it stopped. ABLATIONS (default
# "no-collision no-self-supervision") names the models trained; add "none" to train the full
# recipe again on DATA too (the shipped model was trained on data made on another machine: stop
# 91 found 28 of v4's 33 sequences the same). DEVICE and AT_ONCE as in recipe.sh (AT_ONCE=1 on a
# 2-core CPU); TRAIN_ARGS is added to every train command after the ablation (e.g. "--epochs
# pose=1 --epochs vae=1 --epochs regressor=1" for a quick try). On 2 cores with AT_ONCE=1 about
# 2 h an ablation's recipe (50 VAE epochs of 90 s with three at once, stop 56; the T-shirt's
# nine regressor steps of about 3 minutes, stop 61), and for the T-shirt its capture members'
# regressors (stop 87: the posed planes of the captures' set about 11 minutes, made once, then 5-6
# minutes a seed); since stop 93 the VAEs' epochs take half as long, so about 3.5 h for both
# ablations of the T-shirt (docs/learning.md, "The VAE's training step about twice as fast").
# OUT/fig4.png: the paper's Fig. 4, member 0's VAE of each (collisions on held-out data by epoch).
# The bench (OUT/bench_table1: report.json, chart.png, the table printed) runs on DATA's test
# split and the AMASS-style walk (examples/heldout_walk.sh, made in OUT/heldout where it is not
# there), the networks alone at the high level of detail, two workers; afterwards
#   python benchmarks/report_table.py OUT/bench_table1/report.json --simulated
# prints the table over the simulated frames alone, as docs/learning.md's Table 1s are.
set -euo pipefail
# One compound command, read whole before it runs (see data.sh).
{

usage="usage: table1.sh tshirt|dress OUT [DATA] [CAPTURES]"
GARMENT=${1:?$usage}
OUT=${2:?$usage}
DATA=${3:-scratch/rest}
CAPTURES=${4:-scratch/cap35}
case $GARMENT in  # FIRST: recipe.sh's first step (train all: pose code, VAE, first regressor)
    tshirt) FIRST=T30 ;;
    dress) FIRST=D30 ;;
    *) echo "table1.sh: the garment is tshirt or dress, not '$GARMENT'" >&2; exit 2 ;;
esac
read -r -a ABLATION_LIST <<<"${ABLATIONS:-no-collision no-self-supervision}"
EXTRA=${TRAIN_ARGS:-}
HERE=$(dirname "$0")
models=() firsts=()
for ablation in "${ABLATION_LIST[@]}"; do
    runs=$OUT/runs/$ablation
    model=$OUT/${GARMENT}_$ablation
    recipe=$model
    [ "$GARMENT" = tshirt ] && recipe=$OUT/tshirt_${ablation}_recipe
    # read by recipe.sh and capture_members.sh alike
    export RUNS=$runs VERSION=table1-$ablation TRAIN_ARGS="--ablation $ablation $EXTRA"
    first=$runs/${GARMENT}_${FIRST}_m0  # member 0's first step: Fig. 4's VAE, the capture base
    bash "$HERE/recipe.sh" "$GARMENT" "$recipe" "$DATA"
    if [ "$GARMENT" = tshirt ]; then
        BASE=$first bash "$HERE/capture_members.sh" "$recipe" "$model" "$DATA" "$CAPTURES"
    fi
    models+=(--model "$ablation=$model")
    firsts+=("$first")
done
usd-garment train compare "${firsts[@]}" -o "$OUT/fig4.png"

WALK=$OUT/heldout/amass_walk120.usdc
[ -f "$WALK" ] || bash "$HERE/../heldout_walk.sh" "$OUT/heldout"
usd-garment bench "$WALK" --manifest "$DATA/dataset_${GARMENT}_v4" --split test --workers 2 \
    --lod high --garment "$GARMENT" --method learned --method learned+preimage --method lbs \
    --method lbs+postprocess \
    "${models[@]}" -o "$OUT/bench_table1"
exit
}
