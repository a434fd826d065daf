#!/usr/bin/env bash
# Issue 13's fall table: H-a and H-d (and the shipped P+S model when it exists) on N = 3..14 YCB,
# 20 runs x 2 seeds, open loop vs closed loop, the same scenes. Resumable; extra arguments go to
# shelf-evaluate.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
policies=(h-a h-d)
[ -f examples/pretrained/p_s.zip ] && policies+=(examples/pretrained/p_s.zip)
shelf-evaluate --policies "${policies[@]}" --ns 3-14 --runs 20 --seeds 2 --object-sets ycb \
    --out results/closed_loop/off "$@"
shelf-evaluate --policies "${policies[@]}" --ns 3-14 --runs 20 --seeds 2 --object-sets ycb --closed-loop \
    --out results/closed_loop/on "$@"
for metric in fell_rate sr; do
  python examples/plot_conditions.py --metric $metric --x n --runs results/closed_loop/off:off \
      results/closed_loop/on:on --out "results/closed_loop/${metric}.png"
done
