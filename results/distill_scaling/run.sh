#!/usr/bin/env bash
# The scaling curve of distillation (docs/experiments/distill-scaling.md): the shipped P+S distilled from the
# first 220, 440 and all training states of the dataset's first 35 shards (70 scenes; the last 20 % of the
# scenes are the distillation's validation states), then each model's greedy fall rate per action and SR at
# N = 5, 8, 11 on validation scenes (evaluation seed 2000, YCB), beside the shipped P+S and H-d.
#   bash results/distill_scaling/run.sh            # distil (about 2 min) and measure (about 40 min, resumable)
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}
DIR=results/distill_scaling
MODELS=runs/distill_scaling
mkdir -p "$MODELS"
for n in 220 440 all; do
  extra=()
  [ "$n" != all ] && extra=(--max-states "$n")
  if [ ! -f "$MODELS/p_s_d$n.zip" ]; then
    "$PY" -m shelf_env.training.distill --data data/teacher --max-shards 35 "${extra[@]}" \
      --init examples/pretrained/p_s.zip --out "$MODELS/p_s_d$n.zip" --epochs 8 --val-fraction 0.2 --no-augment --teacher-over labelled --no-progress
  fi
  cp "$MODELS/p_s_d$n.distill.json" "$DIR/p_s_d$n.distill.json"
done
# all states again, each batch drawn through the model's own augmentation (mirror, class permutation)
if [ ! -f "$MODELS/p_s_dall_aug.zip" ]; then
  "$PY" -m shelf_env.training.distill --data data/teacher --max-shards 35 \
    --init examples/pretrained/p_s.zip --out "$MODELS/p_s_dall_aug.zip" --epochs 8 --val-fraction 0.2 --teacher-over labelled --no-progress
fi
cp "$MODELS/p_s_dall_aug.distill.json" "$DIR/p_s_dall_aug.distill.json"
# and with the teacher's margin over every allowed action of a state (the defaults)
if [ ! -f "$MODELS/p_s_dall_aug_m.zip" ]; then
  "$PY" -m shelf_env.training.distill --data data/teacher --max-shards 35 \
    --init examples/pretrained/p_s.zip --out "$MODELS/p_s_dall_aug_m.zip" --epochs 8 --val-fraction 0.2 --no-progress
fi
cp "$MODELS/p_s_dall_aug_m.distill.json" "$DIR/p_s_dall_aug_m.distill.json"
"$PY" -m shelf_env.evaluation.falls examples/pretrained/p_s.zip "$MODELS/p_s_dall_aug.zip" \
  "$MODELS/p_s_dall_aug_m.zip" h-d \
  "$MODELS/p_s_dall.zip" "$MODELS/p_s_d440.zip" "$MODELS/p_s_d220.zip" --ns 8 5 11 --runs 10 --seed 2000 \
  --out "$DIR/falls.json"
"$PY" research/scaling_curve.py "$DIR" --out "$DIR/report.md" --png "$DIR/scaling.png"
