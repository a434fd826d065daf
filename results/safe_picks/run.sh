#!/usr/bin/env bash
# Safe picks (ShelfSortEnv(safe_picks=True), shelf_env.conditions.safe_picks): every policy picks only objects
# whose carry out of the opening clears the other visible objects. The shipped P+S and S models
# beside H-d and H-a, off vs on, the same scenes (issue 10's seed 0 at N = 5, 8, 11, 30 runs); the
# "off" cells are issue 10's (results/models), copied. Resumable; extra arguments go to both
# shelf-evaluate runs (e.g. --ns 3-14 --seeds 3 for issue 10's whole grid).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
policies=(examples/pretrained/v1/p_s.zip examples/pretrained/s.zip h-d h-a)
grid=(--ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb)
shelf-evaluate --policies "${policies[@]}" "${grid[@]}" --out results/safe_picks/off \
    --reuse-cells results/models "$@"
shelf-evaluate --policies "${policies[@]}" "${grid[@]}" --safe-picks --out results/safe_picks/on "$@"
for metric in fell_rate sr; do
  python research/plot_conditions.py --metric $metric --x n --runs results/safe_picks/off:off \
      results/safe_picks/on:on --out "results/safe_picks/${metric}.png"
done
# where the remaining falls come from (results/safe_picks/on/falls.md)
python -m shelf_env.evaluation.traces results/safe_picks/on --policies "${policies[@]}" --ns 8 --limit 6
