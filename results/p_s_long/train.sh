#!/usr/bin/env bash
# P+S trained longer at N = 8: the shipped p_s run (results/training/p_s: 27,500 env steps, its last
# stage N = 8 stopped by the 5000-step stage cap) resumed with that stage's cap raised to 40,000 env
# steps, in results/training/p_s_long (committed; a fresh machine resumes from it, refilling the
# replay buffer). On a machine with many cores and a GPU, parallel envs:
#   bash results/p_s_long/train.sh --n-envs 15            # learner on the GPU (SB3 device "auto")
#   bash results/p_s_long/train.sh --n-envs 1 --amend actor=true   # two CPU cores
# The first run copies results/training/p_s (weights, curriculum, episodes, TensorBoard) to start
# from. Extra arguments go to shelf-train (e.g. --hours, total wall clock including p_s's own).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
if [ ! -f results/training/p_s_long/progress.json ]; then  # shelf-train's own mirror copy, atomic, progress last
  python -c "import pathlib; from shelf_env.cli.train import copy_checkpoint; \
copy_checkpoint(pathlib.Path('results/training/p_s'), pathlib.Path('results/training/p_s_long'))"
fi
shelf-train --out runs/p_s_long --mirror results/training/p_s_long --preset p_s --seed 0 \
    --hours 12 --threads 2 --checkpoint-minutes 10 \
    --amend max_stage_timesteps=40000 --amend eval_every=5000 "$@"
python examples/plot_training.py results/training/p_s_long --png results/training/p_s_long/curve.png
