#!/usr/bin/env bash
# Issue 10's models, one command each, resumable across machines:
#   bash scripts/train_model.sh p_s     # P+S (pick, push-left, push-right)
#   bash scripts/train_model.sh s       # S (pick only, the paper's baseline)
# The "p_s" / "s" preset of shelf_env/training.py (the learning recipe through the curriculum
# N = 1 -> 8), seed 0, two torch threads, a total budget of --hours of wall clock (default 12, over
# as many runs of this command as it takes; extra arguments go to shelf-train).
# The run lives in runs/<model> (with its replay buffer); after every checkpoint (10 min) all but
# the buffer is copied to results/training/<model>, which is committed. On a fresh machine the
# same command resumes from that copy (weights, stage, epsilon) and refills the buffer.
set -euo pipefail
cd "$(dirname "$0")/.."
model="${1:-}"
case "$model" in
  p_s|s) shift ;;
  *) echo "usage: bash scripts/train_model.sh p_s|s [train.py options]" >&2; exit 2 ;;
esac
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-train --out "runs/$model" --mirror "results/training/$model" --preset "$model" --seed 0 \
    --hours 12 --threads 2 --checkpoint-minutes 10 "$@"
python examples/plot_training.py "results/training/$model" --png "results/training/$model/curve.png"
