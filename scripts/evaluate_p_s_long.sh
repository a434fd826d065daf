#!/usr/bin/env bash
# P+S trained longer at N = 8 (scripts/train_p_s_long.sh) against the shipped P+S, H-d and H-a on
# issue 10's seed-0 held-out scenes at N = 5, 8, 11 (30 runs each, YCB objects), greedy, masked.
# The shipped model's and the heuristics' cells are copied from results/models (the same scenes);
# the run's current checkpoint is copied to results/training/p_s_long.zip and evaluated. Resumable;
# extra arguments go to shelf-evaluate (e.g. --ns 3-14 --seeds 3 for issue 10's whole grid).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
cp results/training/p_s_long/model.zip results/training/p_s_long.zip
shelf-evaluate --policies results/training/p_s_long.zip examples/pretrained/p_s.zip h-d h-a --ns 5,8,11 \
    --runs 30 --seeds 1 --object-sets ycb --reuse-cells results/models --out results/p_s_long "$@"
