#!/usr/bin/env bash
# A stricter fall filter under the pick guard (docs/experiments/stricter-filter.md): where the shipped policy's
# greedy falls come from (validation), then the shipped p_s.zip with the same risk model at threshold 0.05 instead
# of 0.1, under the pick guard and the loop breaker, on validation; then (added after its numbers) the tiered filter
# (research.tiered_filter) on validation. The shipped policy's cells are copied (by label and digest) from
# results/pick_guard/val90.
# Usage: bash results/stricter_filter/run.sh [export|sources|val|val2|alternatives|all]   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
out=results/stricter_filter
fit=results/fall_geometry  # round two's fit (fall-geometry.md), the one the shipped risk was exported from
shipped=results/fall_geometry/filter/p_s_geo10.zip+geometry-filter+pick-guard+loop-breaker
geo05="$out/p_s_geo05.zip+geometry-filter+pick-guard+loop-breaker"  # the first candidate (stopped at validation)
old=p_s_geo10+geometry-filter+pick-guard+loop-breaker  # the shipped policy's
# the second candidate
candidate=results/fall_geometry/filter/p_s_geo10.zip+tiered-filter+pick-guard+loop-breaker
new=p_s_geo10+tiered-filter+pick-guard+loop-breaker  # its cells' label
step=${1:-all}
if [[ $step == export || $step == all ]]; then
  cp -p examples/pretrained/p_s.zip "$out/p_s_geo05.zip"
  [ -f "$out/p_s_geo05.geometry_risk.pt" ] || python -m research.fall_geometry export \
      --models "$fit/fit_blockers.models.pt" --name mlp --features "$fit/features_blockers.npz" --threshold 0.05 \
      --out "$out/p_s_geo05.geometry_risk.pt"
fi
if [[ $step == sources || $step == all ]]; then
  # 1. the shipped policy's greedy decisions on validation scenes (seed 2000, N = 8), each probed, by primitive and risk
  python -m research.fall_sources "$shipped" --ns 8 --runs 30 --seed 2000 --out "$out/sources_val.json"
fi
if [[ $step == val || $step == all ]]; then
  # 3. validation: seeds 2000-2002, N = 5, 8, 11
  python -m research.evaluate --policies "$shipped" "$geo05" --ns 5,8,11 --seeds 3 --runs 30 \
      --first-seed 2000 --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" \
      --reuse-cells results/pick_guard/val90
  python -m shelf_env.evaluation.compare "$out/val90" --pair p_s_geo05+geometry-filter+pick-guard+loop-breaker $old \
      --out "$out/val90_pairs.md"
fi
if [[ $step == val2 || $step == all ]]; then
  # 3b. (added after 3) the tiered filter (research.tiered_filter) on the same validation scenes
  python -m research.evaluate --policies "$shipped" "$candidate" --ns 5,8,11 --seeds 3 --runs 30 --first-seed 2000 \
      --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90_tiered" --reuse-cells "$out/val90"
  python -m shelf_env.evaluation.compare "$out/val90_tiered" --pair $new $old --out "$out/val90_tiered_pairs.md"
fi
if [[ $step == alternatives || $step == all ]]; then
  # 5. (added after 3b) the same validation scenes as 1, each pick also compared with its object's lowest-risk cell
  python -m research.fall_sources "$shipped" --ns 8 --runs 30 --seed 2000 --alternatives \
      --out "$out/sources_alt_val.json"
fi
# The held-out steps the plan allowed for a candidate that passed validation were not run: neither passed.
