#!/usr/bin/env bash
# Which unseen objects fall (docs/experiments/ycb-kinds.md): a YCB probe collected on this machine (series 94 and 95,
# the shipped policy driving, into this folder, never into data/teacher), replayed to name the kind of object under
# each labelled pick and the kinds each invalid greedy pick dropped; the same replay of the old probe (the pilot, whose
# states mostly do not replay on another machine) and of series 5's validation split (training objects, a contrast).
# A replay is exact only on the machine that collected the shards: states that differ are counted and left out.
# Usage: bash results/ycb_kinds/run.sh [probe|kinds|carry|pilot|train|all]
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1
out=results/ycb_kinds
wrap=+geometry-filter+pick-guard+loop-breaker
step=${1:-all}
if [[ $step == probe || $step == all ]]; then
  # 0.75 hours on each core, side by side (resumable: shards on disk are skipped)
  for series in 94 95; do
    python -m research.fall_geometry probe --out "$out/probe" --hours 0.75 --series $series --object-set ycb \
        --model "examples/pretrained/p_s.zip$wrap" &
  done
  wait
  python -m shelf_env.privileged.dataset status "$out/probe" > "$out/probe_status.txt"
fi
if [[ $step == kinds || $step == all ]]; then
  python -m research.fall_geometry kinds --data "$out/probe" --series s94,s95 --all-states --out "$out/kinds.json"
fi
if [[ $step == carry || $step == all ]]; then
  # (added after the kinds numbers) whether the camera saw each greedy pick's carry as clear, and the shipped
  # filter's risk of it, by what the pick did
  python -m research.fall_geometry carry --data "$out/probe" --series s94,s95 --kinds "$out/kinds.json" \
      --risk examples/pretrained/p_s.geometry_risk.pt --out "$out/carry.json"
fi
if [[ $step == pilot || $step == all ]]; then
  python -m research.fall_geometry kinds --data results/fall_model_refit/ycb_probe --series s90,s91 --all-states \
      --out "$out/pilot_old_probe.json"
fi
if [[ $step == train || $step == all ]]; then
  # training objects, the same driver: series 5's validation split of the wide refit's pool
  python -m research.fall_geometry kinds --data data/teacher --max-shards s00:55,s01:50,s02:205,s03:638,s04:172,s05:457 \
      --series s05 --out "$out/kinds_train.json"
fi
