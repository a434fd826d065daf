#!/usr/bin/env bash
# Issue 10's models, one command each, resumable across machines:
#   bash scripts/train_model.sh p_s     # P+S (pick, push-left, push-right)
#   bash scripts/train_model.sh s       # S (pick only, the paper's baseline)
#   bash scripts/train_model.sh p_s --name p_s_safe_actor --set safe_picks=true --actor   # a variant
# The "p_s" / "s" preset of shelf_env/training/config.py (the learning recipe through the curriculum
# N = 1 -> 8), seed 0, two torch threads, a total budget of --hours of wall clock (default 12, over
# as many runs of this command as it takes; extra arguments go to shelf-train).
# The run lives in runs/<name> (with its replay buffer; <name> is the preset unless --name is
# given, as the second argument); after every checkpoint (10 min) all but the buffer is copied to
# results/training/<name>, which is committed. On a fresh machine the same command resumes from
# that copy (weights, stage, epsilon) and refills the buffer.
set -euo pipefail
cd "$(dirname "$0")/.."
model="${1:-}"
case "$model" in
  p_s|s) shift ;;
  *) echo "usage: bash scripts/train_model.sh p_s|s [--name NAME] [train.py options]" >&2; exit 2 ;;
esac
name="$model"
if [ "${1:-}" = "--name" ]; then
  name="${2:?--name needs a value}"
  shift 2
fi
case "$name" in
  *[!A-Za-z0-9_.-]*|"") echo "train_model.sh: --name must be letters, digits, _ . - only, got '$name'" >&2; exit 2 ;;
esac
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-train --out "runs/$name" --mirror "results/training/$name" --preset "$model" --seed 0 \
    --hours 12 --threads 2 --checkpoint-minutes 10 "$@"
python examples/plot_training.py "results/training/$name" --png "results/training/$name/curve.png"
