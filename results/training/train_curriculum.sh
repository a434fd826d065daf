#!/usr/bin/env bash
# The committed curriculum run of the README: P+S on ShelfSort-v0, 2 hours of wall clock on CPU.
# Learning rate 1e-3 (the paper's 1e-4 barely moved the greedy policy in 1000 CPU steps);
# epsilon decays over 1000 steps per stage and a stage lasts at least 1000 steps, so that the
# success that promotes a stage is the greedy policy's rather than masked exploration's.
# One torch thread: the committed run shared the two cores with a second run and other work.
# Re-running the same command resumes from the last checkpoint in runs/curriculum_gated until the
# budget is spent; then plot_training.py draws docs/training_curve.png from episodes.csv.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
python examples/train.py --out runs/curriculum_gated --hours 2 --threads 1 --learning-rate 1e-3 \
    --exploration-timesteps 1000 --min-stage-timesteps 1000 "$@"
python examples/plot_training.py runs/curriculum_gated --png docs/training_curve.png
