#!/usr/bin/env bash
# Issue 10: copy every finished model run (results/training/p_s, results/training/s; its curriculum
# is over) to examples/pretrained/<model>.zip and write examples/pretrained/README.md, the model
# card, with the evaluation table once scripts/evaluate_models.sh has evaluated the shipped models.
# Order: train_model.sh p_s|s -> ship_models.sh -> evaluate_models.sh -> ship_models.sh (the card's table).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
args=()
if [ -f results/models/results.json ] && python -c "import json,sys; sys.exit(0 if json.load(open('results/models/results.json'))['config'].get('complete') else 1)"; then
  args+=(--results results/models)
fi
python -m shelf_env.training.ship "${args[@]}" "$@"
