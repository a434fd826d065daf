#!/usr/bin/env bash
# Play a fine-tuned P+S checkpoint with the loop breaker on issue 10's YCB grid (N = 3..14, 30 runs,
# seeds 0 and 1) under issue 13's recommended setting (closed loop with the watch's defaults, safe
# picks), beside the shipped P+S (with and without the breaker) and H-a / H-d (with and without),
# whose cells are reused from results/loop_breaker/closed_safe (the same scenes), and write
# OUT/report.md against them. Resumable cell by cell.
#   bash results/loop_breaker/evaluate_closed_safe.sh ZIP OUT     (the policy is named after ZIP's file name)
set -euo pipefail
cd "$(dirname "$0")/../.."
if [ $# -ne 2 ] || [ ! -f "$1" ]; then
    echo "usage: bash results/loop_breaker/evaluate_closed_safe.sh ZIP OUT (ZIP: a PixelDoubleDQN checkpoint; got: $*)" >&2
    exit 2
fi
. .venv/bin/activate
zip=$1 out=$2 name=$(basename "$1" .zip)
ps=examples/pretrained/v1/p_s.zip
shelf-evaluate --policies "$zip+loop-breaker" "$ps+loop-breaker" "$ps" h-a h-a+loop-breaker h-d h-d+loop-breaker \
    --ns 3-14 --runs 30 --seeds 2 --object-sets ycb --closed-loop '{}' --safe-picks --out "$out" \
    --reuse-cells results/loop_breaker/closed_safe --workers 2
python -m shelf_env.evaluation.report "$out" --learned "$name+loop-breaker" --pick-only p_s+loop-breaker \
    --heuristics h-d h-a h-d+loop-breaker h-a+loop-breaker
