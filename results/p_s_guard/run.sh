#!/usr/bin/env bash
# P+S fine-tuned under the privileged supervisor (results/p_s_guard/train.sh), its last checkpoint
# (results/training/p_s_guard), against the same run without the supervisor (p_s_la), P+S trained
# longer (p_s_long), the shipped P+S, H-d and H-a on issue 10's seed-0 held-out scenes at N = 5, 8, 11
# (30 runs each, YCB objects, greedy, no supervisor): results/p_s_guard. Every cell is run here, none
# reused: PyBullet's trajectories are bit-identical on one machine but not across machines (5 of
# H-d's 30 N = 8 episodes ended differently on another machine), so all policies compared are
# played on the same machine. Extra arguments go to shelf-evaluate.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
cp results/training/p_s_guard/model.zip results/training/p_s_guard.zip
shelf-evaluate --policies results/training/p_s_guard.zip results/training/p_s_la.zip results/training/p_s_long.zip \
    examples/pretrained/v1/p_s.zip h-d h-a --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/p_s_guard "$@"
