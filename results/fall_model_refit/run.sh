#!/usr/bin/env bash
# The geometry fall model refit on the grown teacher dataset (docs/experiments/fall-model-refit.md): round two's
# features and MLP recipe (results/fall_geometry) on every shard of the dataset at this experiment's start except
# round two's test set, which stays the test set; the refit beside the shipped geometry risk on the same validation
# and test labels; then, by the page's rule, the refit as the shipped policy's filter at the shipped threshold 0.1
# on the validation scenes, and on issue 10's held-out scenes if it passes there.
# Usage: bash results/fall_model_refit/run.sh [features|fit|export|val|greedy|probe|greedy_ycb|all]   |   ... open|closed|falls
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
export OMP_NUM_THREADS=1
out=results/fall_model_refit
pool=s00:55,s01:50,s02:205,s03:638,s04:172,s05:457  # the dataset when this experiment started (1,577 shards)
fresh=s03:95,s04:59  # round two's test set: the shards of these ...
after=s00:55,s01:50,s02:205,s03:54,s04:10  # ... that the fall model's 374 shards leave out (s03_00054-94, s04_00010-58)
shipped_risk=examples/pretrained/p_s.geometry_risk.pt  # round two's MLP at 0.1, the shipped filter's
geo=results/fall_geometry/filter/p_s_geo10.zip  # the shipped p_s.zip + its geometry risk, the label it was played as
wrap=+geometry-filter+pick-guard+loop-breaker
shipped="$geo$wrap"
old=p_s_geo10$wrap  # the shipped policy's cells' label
candidate="$out/p_s_georefit.zip$wrap"
new=p_s_georefit$wrap
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
split=(--data data/teacher --max-shards "$pool" --val-fraction 0.2 --fresh "$fresh" --fresh-after "$after")
step=${1:-all}
if [[ $step == features || $step == fit || $step == export || $step == all ]]; then
  geometry_refit "$step" "$out" p_s_georefit "${split[@]}"  # results/heldout.sh
fi
if [[ $step == val || $step == all ]]; then
  # validation: seeds 2000-2002, N = 5, 8, 11; the shipped policy's cells from results/push_guard/val90
  validate $out "$candidate" "$new" $old results/push_guard/val90 "$shipped"
fi
if [[ $step == open || $step == closed || $step == falls ]]; then
  # held-out: the open-loop grid, closed loop + safe picks, the greedy fall rate at N = 8 (results/heldout.sh)
  after_validation "$step" $out "$candidate" "$new" $old $ref research.fall_geometry "$shipped" "${others[@]}"
fi
if [[ $step == greedy || $step == all ]]; then
  # (added after the validation numbers) both risks on the picks the shipped policy made: series 5's greedy picks in
  # the refit's validation split
  python -m research.fall_geometry greedy "${split[@]}" --series s05 --risk "shipped=$shipped_risk" \
      --risk "refit=$out/p_s_georefit.geometry_risk.pt" --out "$out/greedy.json"
fi
if [[ $step == probe ]]; then
  # (added after the greedy picks' numbers) a YCB probe set, never part of data/teacher: the shipped policy driving,
  # series 90 for 30 minutes and series 91 for 45 minutes, one core each, side by side (resumable: shards on disk are
  # skipped)
  python -m research.fall_geometry probe --out "$out/ycb_probe" --hours 0.5 --series 90 \
      --model "examples/pretrained/p_s.zip$wrap" &
  python -m research.fall_geometry probe --out "$out/ycb_probe" --hours 0.75 --series 91 \
      --model "examples/pretrained/p_s.zip$wrap"
  wait
fi
if [[ $step == greedy_ycb || $step == all ]]; then
  # both risks on the probe's picks, every state
  python -m research.fall_geometry greedy --data "$out/ycb_probe" --series s90,s91 --all-states \
      --risk "shipped=$shipped_risk" --risk "refit=$out/p_s_georefit.geometry_risk.pt" --out "$out/greedy_ycb.json"
fi
