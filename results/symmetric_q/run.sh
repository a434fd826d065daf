#!/usr/bin/env bash
# The distilled model of the curve's fifth point acting on its Q-maps averaged over the cabinet's 12 symmetries
# (research/symmetric_q.py, docs/experiments/symmetric-q.md), on issue 10's held-out scenes (open loop, YCB, all
# three seeds at N = 5, 8, 11), beside the same model plain, its fine-tune and the heuristics (their cells copied
# from results/distill_test), and the greedy action's falls per action on the first 30 scenes (seed 0) at N = 8.
# One configuration (all 12 views), chosen before any scene was played; nothing here chose between variants.
#   bash results/symmetric_q/run.sh [--workers 1]     # resumable
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}
OUT=results/symmetric_q
M=runs/distill_scaling
D=$M/p_s_dagger115_aug_mpa_r2_ce1.zip       # the curve's fifth point
FT=$M/p_s_dagger115_aug_mpa_r2_ce1_ft5k.zip # its 5,000-step fine-tune, for reference
[ -f $D ] || bash results/distill_scaling/run.sh
[ -f $FT ] || bash results/distill_test/run.sh "$@"
FALLS="import research.symmetric_q, sys; from shelf_env.evaluation.falls import main; sys.exit(main())"
for policy in $D $D+symmetric $FT; do
  "$PY" -c "$FALLS" $policy --ns 8 --runs 30 --seed 0 --out $OUT/falls.json
done
# +symmetric on the held-out grid; the plain model, its fine-tune, P+S, the heuristics: cells of results/distill_test
"$PY" -m research.evaluate --policies h-d h-a examples/pretrained/v1/p_s.zip $D $D+symmetric $FT --ns 5,8,11 \
  --runs 30 --seeds 3 --object-sets ycb --out $OUT --reuse-cells results/distill_test "$@"
# the table: falls per action at N = 8 (first 30 scenes of seed 0), SR and the paired margin over the better heuristic
"$PY" research/scaling_curve.py $OUT --reports results/distill_scaling --evaluation $OUT --out $OUT/table.md
