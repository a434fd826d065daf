#!/usr/bin/env bash
# Issue 13's fall table: H-a and H-d (and the shipped P+S model when it exists) on N = 3..14 YCB,
# 30 runs x 3 seeds (issue 10's grid), open loop vs closed loop, the same scenes. Resumable; extra
# arguments go to shelf-evaluate. The open-loop cells are those of issue 10's evaluation
# (scripts/evaluate_models.sh, results/models), copied (--reuse-cells) instead of run again: the
# same scenes, but played on other machines (PyBullet differs by CPU; see the README), so compare
# with care or delete results/closed_loop/off/cells to run them here. scripts/closed_loop_seed0.sh
# is the two-core version (seed 0, N = 3, 5, 8, 11, 14, everything on one machine).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
policies=(h-a h-d)
# PS=0 leaves the shipped P+S model out (on two cores its 36 closed-loop cells take hours)
if [ "${PS:-1}" = 1 ] && [ -f examples/pretrained/p_s.zip ]; then policies+=(examples/pretrained/p_s.zip); fi
reuse=()
[ -d results/models/cells ] && reuse=(--reuse-cells results/models)
shelf-evaluate --policies "${policies[@]}" --ns 3-14 --runs 30 --seeds 3 --object-sets ycb \
    --out results/closed_loop/off "${reuse[@]}" "$@"
shelf-evaluate --policies "${policies[@]}" --ns 3-14 --runs 30 --seeds 3 --object-sets ycb --closed-loop \
    --out results/closed_loop/on "$@"
for metric in fell_rate sr; do
  python examples/plot_conditions.py --metric $metric --x n --runs results/closed_loop/off:off \
      results/closed_loop/on:on --out "results/closed_loop/${metric}.png"
done
