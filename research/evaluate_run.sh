#!/usr/bin/env bash
# Evaluate a training run's current checkpoint against the shipped P+S, H-d and H-a on issue 10's
# seed-0 held-out scenes at N = 5, 8, 11 (30 runs each, YCB objects), greedy, masked:
#   bash research/evaluate_run.sh NAME [shelf-evaluate arguments...]
# copies results/training/NAME/model.zip (the run's committed mirror) to results/training/NAME.zip
# and writes results/NAME/. The shipped model's and the heuristics' cells are copied from
# results/models (the same scenes). Resumable cell by cell; later arguments override these (e.g.
# --policies, --reuse-cells, or --ns 3-14 --seeds 3 for issue 10's whole grid).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 1 ] || [ ! -f "results/training/$1/model.zip" ]; then
  echo "usage: bash research/evaluate_run.sh NAME [shelf-evaluate args]: results/training/NAME/model.zip needed" >&2
  exit 2
fi
name=$1; shift
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
cp "results/training/$name/model.zip" "results/training/$name.zip"
shelf-evaluate --policies "results/training/$name.zip" examples/pretrained/v1/p_s.zip h-d h-a --ns 5,8,11 \
    --runs 30 --seeds 1 --object-sets ycb --reuse-cells results/models --out "results/$name" "$@"
