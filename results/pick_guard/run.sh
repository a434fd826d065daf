#!/usr/bin/env bash
# The pick guard (docs/experiments/pick-guard.md): the P+S shipped before it with and without +pick-guard
# (research.pick_guard when the cells were played, shelf_env.pick_guard since) on validation scenes, then on issue 10's held-out scenes: the whole open-loop grid, then closed
# loop + safe picks on seed 0. The shipped policy's cells are copied (by label and digest) from where they were
# played; then the guarded policy's greedy fall rate at N = 8 (each decision probed in a forked copy).
# Usage: bash results/pick_guard/run.sh [val|open|closed|falls|all]   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
out=results/pick_guard
geo=results/fall_geometry/filter/p_s_geo10.zip  # the shipped p_s.zip + its geometry risk, the label they were played as
shipped="$geo+geometry-filter+loop-breaker"
candidate="$geo+geometry-filter+pick-guard+loop-breaker"
new=p_s_geo10+geometry-filter+pick-guard+loop-breaker  # the candidate's cells' label
old=p_s_geo10+geometry-filter+loop-breaker  # the shipped policy's
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
step=${1:-all}
if [[ $step == val || $step == all ]]; then
  # 1. validation: seeds 2000-2002, N = 5, 8, 11
  python -m research.evaluate --policies "$shipped" "$candidate" --ns 5,8,11 --seeds 3 --runs 30 \
      --first-seed 2000 --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" \
      --reuse-cells results/fall_geometry/val90_lb
  python -m shelf_env.evaluation.compare "$out/val90" --pair $new $old --out "$out/val90_pairs.md"
fi
if [[ $step == open || $step == all ]]; then
  # 2. held-out, open loop: issue 10's grid (seeds 0-2, N = 3..14); every policy but the candidate copied
  heldout open $out "$candidate" $new $old $ref results/models_v4/open "$shipped" "${others[@]}"
fi
if [[ $step == closed || $step == all ]]; then
  # 3. held-out, closed loop + safe picks: seed 0, N = 3..14
  heldout closed $out "$candidate" $new $old $ref results/models_v4/closed_safe "$shipped" \
      "$ref=examples/pretrained/p_s.zip" h-d h-a
fi
if [[ $step == falls || $step == all ]]; then
  # 4. the guarded policy's greedy fall rate per decision at N = 8, the first 30 held-out scenes of seed 0 (resumable)
  python -m shelf_env.evaluation.falls "$candidate" --ns 8 --runs 30 --seed 0 --out "$out/falls30.json"
fi
