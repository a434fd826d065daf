#!/usr/bin/env bash
# The pick guard (docs/experiments/pick-guard.md): the shipped P+S with and without research.pick_guard's
# +pick-guard on validation scenes, then on issue 10's held-out scenes at N = 5, 8, 11 (open loop).
# The shipped policy's cells are copied (by label and digest) from where they were played.
# Usage: bash results/pick_guard/run.sh [val|heldout|all]   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
out=results/pick_guard
geo=results/fall_geometry/filter/p_s_geo10.zip  # the shipped p_s.zip + its geometry risk, the label they were played as
shipped="$geo+geometry-filter+loop-breaker"
candidate="$geo+geometry-filter+pick-guard+loop-breaker"
step=${1:-all}
if [[ $step == val || $step == all ]]; then
  # 1. validation: seeds 2000-2002, N = 5, 8, 11
  python -m research.evaluate --policies "$shipped" "$candidate" --ns 5,8,11 --seeds 3 --runs 30 \
      --first-seed 2000 --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" \
      --reuse-cells results/fall_geometry/val90_lb
  python -m shelf_env.evaluation.compare "$out/val90" --pair p_s_geo10+geometry-filter+pick-guard+loop-breaker \
      p_s_geo10+geometry-filter+loop-breaker --out "$out/val90_pairs.md"
fi
if [[ $step == heldout || $step == all ]]; then
  # 2. held-out: issue 10's seeds 0-2, N = 5, 8, 11, open loop
  python -m research.evaluate --policies "$shipped" "$candidate" --ns 5,8,11 --seeds 3 --runs 30 \
      --object-sets ycb --workers "${WORKERS:-1}" --out "$out/heldout" --reuse-cells results/models_v4/open
  python -m shelf_env.evaluation.compare "$out/heldout" --pair p_s_geo10+geometry-filter+pick-guard+loop-breaker \
      p_s_geo10+geometry-filter+loop-breaker --out "$out/heldout_pairs.md"
fi
