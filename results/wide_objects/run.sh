#!/usr/bin/env bash
# The fall model on a wide object set (docs/experiments/wide-objects.md): a series of wide training objects
# (`train-wide`: the training shapes over ranges spanning the test set's sizes and masses), collected into this
# folder, never into data/teacher; round two's fall-model recipe refit on the refit's pool plus those shards; the
# wide refit beside the shipped risk and the refit on the test set, the YCB probe and the wide series' validation
# scenes; then, by the page's rule, the wide refit as the shipped policy's filter at 0.1 on the validation scenes,
# and on issue 10's held-out scenes if it passes there.
# Usage: bash results/wide_objects/run.sh [collect|features|fit|export|greedy_ycb|greedy_wide|greedy_train|val|all]
#        ... open|closed|falls   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
export OMP_NUM_THREADS=1
out=results/wide_objects
refit=results/fall_model_refit  # the refit on the same pool without the wide shards, and the YCB probe
pool=s00:55,s01:50,s02:205,s03:638,s04:172,s05:457  # the refit's pool
fresh=s03:95,s04:59  # round two's test set: the shards of these ...
after=s00:55,s01:50,s02:205,s03:54,s04:10  # ... that the fall model's 374 shards leave out
shipped_risk=examples/pretrained/p_s.geometry_risk.pt
refit_risk=$refit/p_s_georefit.geometry_risk.pt
wide_risk=$out/p_s_geowide.geometry_risk.pt
wrap=+geometry-filter+pick-guard+loop-breaker
shipped="results/fall_geometry/filter/p_s_geo10.zip$wrap"  # the shipped policy, as its cells are labelled
old=p_s_geo10$wrap
candidate="$out/p_s_geowide.zip$wrap"
new=p_s_geowide$wrap
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
split=(--data data/teacher --max-shards "$pool" --val-fraction 0.2 --fresh "$fresh" --fresh-after "$after"
       --extra-data "$out/shards")
risks=(--risk "shipped=$shipped_risk" --risk "refit=$refit_risk" --risk "wide=$wide_risk")
step=${1:-all}
if [[ $step == collect ]]; then
  # series 92 and 93, 1.3 hours each, one core each, side by side (resumable: shards on disk are skipped)
  for series in 92 93; do
    python -m research.fall_geometry probe --out "$out/shards" --hours 1.3 --series $series --object-set train-wide \
        --model "examples/pretrained/p_s.zip$wrap" &
  done
  wait
fi
if [[ $step == features || $step == fit || $step == export || $step == all ]]; then
  geometry_refit "$step" "$out" p_s_geowide "${split[@]}"  # results/heldout.sh
fi
if [[ $step == greedy_ycb || $step == all ]]; then
  # the three risks on the YCB probe's greedy picks and other picks, every state
  python -m research.fall_geometry greedy --data $refit/ycb_probe --series s90,s91 --all-states "${risks[@]}" \
      --out "$out/greedy_ycb.json"
fi
if [[ $step == greedy_wide || $step == all ]]; then
  # the three risks on the wide series' validation scenes (the wide refit did not train on them)
  python -m research.fall_geometry greedy "${split[@]}" --series s92,s93 "${risks[@]}" --out "$out/greedy_wide.json"
fi
if [[ $step == greedy_train || $step == all ]]; then
  # (added after the YCB numbers) the three risks on series 5's validation split: training objects, the same driver
  python -m research.fall_geometry greedy "${split[@]}" --series s05 "${risks[@]}" --out "$out/greedy_train.json"
fi
if [[ $step == val ]]; then
  # only if the page's reading says the wide refit carries better (validation: seeds 2000-2002, N = 5, 8, 11)
  validate $out "$candidate" "$new" $old results/push_guard/val90 "$shipped"
fi
if [[ $step == open || $step == closed || $step == falls ]]; then
  after_validation "$step" $out "$candidate" "$new" $old $ref research.fall_geometry "$shipped" "${others[@]}"
fi
