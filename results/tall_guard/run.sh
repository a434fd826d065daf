#!/usr/bin/env bash
# Carries blocked by objects taller than any training object (docs/experiments/tall-guard.md): candidate
# research.tall_guard innermost under the shipped wrappers on the validation scenes, and on issue 10's held-out scenes
# if it passes there. The shipped policy's cells are copied (by label and digest) from where they were played.
# Usage: bash results/tall_guard/run.sh val   |   bash results/tall_guard/run.sh open|closed|falls
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
export OMP_NUM_THREADS=1
out=results/tall_guard
geo=results/fall_geometry/filter/p_s_geo10.zip  # the shipped p_s.zip + its geometry risk, the label it was played as
wrap=+geometry-filter+pick-guard+loop-breaker
shipped="$geo$wrap"
old=p_s_geo10$wrap  # the shipped policy's cells' label
candidate="$geo+tall-guard$wrap"
new=p_s_geo10+tall-guard$wrap
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
step=${1:-val}
if [[ $step == val ]]; then
  # validation: seeds 2000-2002, N = 5, 8, 11; the shipped policy's cells from results/push_guard/val90
  validate $out "$candidate" "$new" $old results/push_guard/val90 "$shipped"
fi
if [[ $step == open || $step == closed || $step == falls ]]; then
  # held-out: the open-loop grid, closed loop + safe picks, the greedy fall rate at N = 8 (results/heldout.sh)
  after_validation "$step" $out "$candidate" "$new" $old $ref research.tall_guard "$shipped" "${others[@]}"
fi
