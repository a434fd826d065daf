#!/usr/bin/env bash
# The learned fall filter (research.fall_risk) for the shipped P+S, from scratch to issue 10's table:
#   1. collect: two processes label picks in forked copies of training scenes (training objects,
#      N = 3..14, seeds of their own), driven by p_s.zip; one file per episode under runs/fall_risk/
#      (not committed: ~1 MB per episode), resumable; each stops after HOURS (default 0.55).
#   2. train: the fall-risk FCN, started from p_s.zip's pick FCN, on those episodes (the last 15 % held
#      out to choose the epoch and the threshold) -> results/fall_filter/model/p_s.fall_risk.pt, beside
#      a copy of examples/pretrained/v1/p_s.zip (a `<zip>+fall-filter` policy reads the model beside it).
#      It is an experiment, not shipped: the shipped p_s.zip stays unfiltered. Then the filter's effect
#      on p_s's choice among the probed picks of the held-out episodes -> results/fall_filter/greedy_check.json
#   3. evaluate: results/fall_filter/model/p_s.zip+fall-filter under issue 10's open loop (seed 0, 30
#      YCB scenes per N = 3..14), beside the cells of results/models (p_s, s, h-d, h-a)
#      -> results/fall_filter/, report.md
# Each step skips what is on disk; extra arguments go to shelf-evaluate.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
export OMP_NUM_THREADS=1
data=runs/fall_risk
dir=results/fall_filter/model
model=$dir/p_s.fall_risk.pt
out=results/fall_filter
mkdir -p "$dir"
cp -p examples/pretrained/v1/p_s.zip "$dir/p_s.zip"
if [ ! -f "$model" ]; then
    mkdir -p "$data"
    pids=()
    for shard in 0 1; do
        python -m research.fall_risk collect --out "$data" --episodes 200 --shard "$shard" \
            --hours "${HOURS:-0.55}" > "$data.shard$shard.log" 2>&1 &
        pids+=($!)
    done
    for pid in "${pids[@]}"; do wait "$pid"; done
    OMP_NUM_THREADS=2 python -m research.fall_risk train --data "$data" --out "$model" \
        --init examples/pretrained/v1/p_s.zip --epochs "${EPOCHS:-12}"
    python -m research.fall_risk check --data "$data" --model "$model" --checkpoint examples/pretrained/v1/p_s.zip \
        --out "$out/greedy_check.json"
fi
ps=examples/pretrained/v1/p_s.zip
grid=(--ns 3-14 --runs 30 --seeds 1 --object-sets ycb --out "$out" --workers 2)
python -m research.evaluate --policies "$dir/p_s.zip+fall-filter" "$ps" examples/pretrained/s.zip h-d h-a "${grid[@]}" \
    --reuse-cells results/models "$@"
python -m shelf_env.evaluation.report "$out" --learned p_s+fall-filter --pick-only s --heuristics h-d h-a
