#!/usr/bin/env bash
# Is the fall visible? (docs/experiments/fall-visibility.md) The fall model of results/teacher_fall_filter on the
# camera's heightmap and on an unoccluded top-down heightmap (shelf_env.privileged.topdown), same states, same labels:
#   1. replay: the first 3,349 training states and all held-out states of the fall model's split (the 374 shards the
#      fourteenth session started with), each replayed from its scene's seed and actions -> topdown/sNN_NNNNN.npz
#      (the top-down observation of each state and whether the replayed camera observation equals the stored one;
#      committed, since a replay is bit-identical only on the machine that collected the shard)
#   2. compare: the fall model trained on each view (8 epochs from the shipped P+S's pick FCN, the best held-out
#      epoch), held-out AUC and the offline check of docs/experiments/object-fall-penalty.md -> compare.json,
#      models/{camera,topdown}.fall_risk.pt
# Each step skips what is on disk; PARTS (default 1) replay processes.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
export OMP_NUM_THREADS=1
out=results/fall_visibility
split=(--data data/teacher --replays "$out/topdown" --max-shards s00:55,s01:50,s02:205,s03:54,s04:10
       --max-states 3349 --val-fraction 0.2)
parts=${PARTS:-1}
for ((k = 0; k < parts; k++)); do
    python -m research.fall_visibility replay "${split[@]}" --part "$k/$parts" &
done
wait
[ -f "$out/compare.json" ] || python -m research.fall_visibility compare "${split[@]}" \
    --checkpoint examples/pretrained/p_s.zip --out "$out/compare.json" --models "$out/models"
#   3. the same from scratch (both models; their start was the camera-trained pick FCN) -> compare_scratch.json
[ -f "$out/compare_scratch.json" ] || python -m research.fall_visibility compare "${split[@]}" \
    --checkpoint examples/pretrained/p_s.zip --init none --out "$out/compare_scratch.json"
#   4. how well the nearest labelled pick of the same object predicts a pick (no model) -> neighbours.json
[ -f "$out/neighbours.json" ] || python -m research.fall_visibility neighbours --data data/teacher \
    --max-shards s00:55,s01:50,s02:205,s03:54,s04:10 --val-fraction 0.2 --out "$out/neighbours.json"
