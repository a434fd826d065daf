#!/usr/bin/env bash
# The committed curriculum run of the README: P+S on ShelfSort-v0, 2 hours of wall clock on CPU,
# learning rate 1e-3 (the paper's 1e-4 barely moved the greedy policy in 1000 CPU steps).
# Re-running the same command resumes from the last checkpoint in runs/curriculum until the
# budget is spent (one torch thread: the committed run shared the machine with other work);
# then plot_training.py draws docs/training_curve.png from episodes.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
python examples/train.py --out runs/curriculum --hours 2 --threads 1 --learning-rate 1e-3 "$@"
python examples/plot_training.py runs/curriculum --png docs/training_curve.png
