#!/usr/bin/env bash
# The test-time loop breaker (sb3_pixeldqn.loop_breaker.LoopBreaker, its defaults: a cell is banned
# once 3 actions of its map lie within 1 cell of it). Every policy is evaluated with it and without
# it, so that P+S+LB is judged against H+LB and not only against the bare heuristics. The policies
# are the shipped P+S model, H-a and H-d. The setting is issue 13's recommended one (closed loop
# with the watch's defaults, safe picks), on issue 10's YCB grid (N = 3..14, 30 runs), seeds 0 and
# 1. The breaker was designed from seed 0's P+S loops, so the held-out claim is seed 1's.
#
# The cells without the breaker come from results/closed_loop/on_deeper_safe where it has them
# (the same machine type; P+S there has seed 0 only). Resumable; extra arguments go to
# shelf-evaluate, e.g. --workers 2 (about 90 min on two cores for the 72 cells it adds).
# Writes results/loop_breaker/closed_safe/{results.csv,results.json,sr_ae_mae_ycb.png} and
# report.md, which judges P+S+LB against all four heuristic variants and against P+S itself (in
# the report's pick-only column).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
ps=examples/pretrained/v1/p_s.zip
out=results/loop_breaker/closed_safe
policies=("$ps+loop-breaker" "$ps" h-a h-a+loop-breaker h-d h-d+loop-breaker)
shelf-evaluate --policies "${policies[@]}" --ns 3-14 --runs 30 --seeds 2 --object-sets ycb \
    --closed-loop '{}' --safe-picks --out "$out" --reuse-cells results/closed_loop/on_deeper_safe "$@"
python -m shelf_env.evaluation.report "$out" --learned p_s+loop-breaker --pick-only p_s \
    --heuristics h-d h-a h-d+loop-breaker h-a+loop-breaker
