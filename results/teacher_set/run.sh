#!/usr/bin/env bash
# The teacher's ties and a set target for the teacher term (docs/experiments/teacher-set.md): how often a labelled
# action does as well as the teacher's off its square (60 shards of the twenty-sixth session's 1,503, drawn at seed
# 0), then model G, the scaling curve's eleventh point with --teacher-set and nothing else changed (plain and averaged
# from one run, checkpointed each epoch into a resume file here: commit it when a session ends mid-run).
# Its averaged weights are candidate G under the shipped wrappers: bash results/own_states/run.sh g / valg.
# Then (diag) both runs' averaged models (candidates A and G, as committed) on the same validation states (the last
# fifth of the 649 shards' scenes, which neither trained on): the distillation loss with the teacher alone, and how
# often each greedy action lies in the teacher's square (teacher_near) or a tie's (teacher_set_choice); the soup
# research/model_soup.py also writes is a by-product, not played.
#   bash results/teacher_set/run.sh [ties|g|diag|all]
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=${PYTHON:-.venv/bin/python}
DIR=results/teacher_set
M=runs/distill_scaling
step=${1:-all}
mkdir -p "$M"
if [[ $step == ties || $step == all ]]; then
  OMP_NUM_THREADS=1 "$PY" -m research.teacher_ties data/teacher \
    --max-shards s00:55,s01:50,s02:205,s03:602,s04:172,s05:419 --shards 60 --seed 0 --out "$DIR/ties.md"
fi
g=p_s_dagger594_aug_mpa_r2_ce1_set
if [[ $step == g || $step == all ]]; then
  [ -f "$M/${g}_avg4.zip" ] || OMP_NUM_THREADS=2 MKL_NUM_THREADS=2 "$PY" -m shelf_env.training.distill \
    --data data/teacher --max-shards s00:55,s01:50,s02:205,s03:184,s04:155 --init examples/pretrained/v1/p_s.zip \
    --out "$M/${g}_avg4.zip" --epochs 8 --val-fraction 0.2 --anchor 1.0 --teacher-radius 2 --teacher-temperature 1 \
    --average-last 4 --last-out "$M/$g.zip" --resume-file "$DIR/${g}_avg4.resume.pt" --teacher-set
  cp "$M/$g.distill.json" "$M/${g}_avg4.distill.json" "$DIR/"
fi
if [[ $step == diag || $step == all ]]; then
  OMP_NUM_THREADS=2 "$PY" research/model_soup.py results/own_states/p_s_dagger594_aug_mpa_r2_ce1_avg4.zip \
    results/own_states/${g}_avg4.zip --out "$M/soup_a_g.zip" \
    --val-shards s00:55,s01:50,s02:205,s03:184,s04:155 --teacher-radius 2 --teacher-temperature 1 > "$DIR/val_states.jsonl"
fi
