#!/usr/bin/env bash
# Objects at a region's edge last (docs/experiments/edge-guard.md): what the shipped policy's greedy picks did in
# series 5 of the teacher dataset by the borderline reading (training scenes), its picks on training-seed YCB scenes
# judged by the env's rule, then candidate E (research.edge_guard innermost under the shipped wrappers) on the
# validation scenes, and on issue 10's held-out scenes if it passes there. The shipped policy's cells are copied (by
# label and digest) from where they were played.
# Usage: bash results/edge_guard/run.sh [stats|live|val|all]   |   bash results/edge_guard/run.sh open|closed|falls
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
export OMP_NUM_THREADS=1
out=results/edge_guard
geo=results/fall_geometry/filter/p_s_geo10.zip  # the shipped p_s.zip + its geometry risk, the label it was played as
wrap=+geometry-filter+pick-guard+loop-breaker
shipped="$geo$wrap"
old=p_s_geo10$wrap  # the shipped policy's cells' label
candidate="$geo+edge-guard$wrap"
new=p_s_geo10+edge-guard$wrap
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
step=${1:-all}
if [[ $step == stats || $step == all ]]; then
  python -m research.edge_guard stats data/teacher --max-shards s05:200 --out $out/series5.md
fi
if [[ $step == live || $step == all ]]; then
  # training seeds 7000-7019 (no evaluation seed), N = 8, YCB objects
  python -m research.edge_guard live --policy "$shipped" --n 8 --runs 20 --first-seed 7000 --object-set ycb \
      --out $out/live.md
fi
if [[ $step == val || $step == all ]]; then
  # validation: seeds 2000-2002, N = 5, 8, 11; the shipped policy's cells from results/push_guard/val90
  validate $out "$candidate" "$new" $old results/push_guard/val90 "$shipped"
fi
if [[ $step == open || $step == closed || $step == falls ]]; then
  # held-out: the open-loop grid, closed loop + safe picks, the greedy fall rate at N = 8 (results/heldout.sh)
  after_validation "$step" $out "$candidate" "$new" $old $ref research.edge_guard "$shipped" "${others[@]}"
fi
