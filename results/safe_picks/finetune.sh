#!/usr/bin/env bash
# Fine-tune the shipped P+S model under the env's safe picks (shelf_env.conditions.safe_picks): a new run from
# examples/pretrained/v1/p_s.zip's weights (shelf-train --init-from) at N = 8, its buffer refilled from
# scratch, exploration from 0.1, the "p_s" preset otherwise; resumable like train_model.sh (runs/p_s_safe,
# mirrored to results/training/p_s_safe). Then P+S fine-tuned vs shipped, both with safe picks, on
# issue 10's seed-0 scenes at N = 5, 8, 11 (results/safe_picks/on). Extra arguments go to shelf-train
# (e.g. --hours 1).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-train --out runs/p_s_safe --mirror results/training/p_s_safe --preset p_s --seed 0 --threads 2 \
    --init-from examples/pretrained/v1/p_s.zip --set safe_picks=true --start-objects 8 \
    --set exploration_initial_eps=0.1 --checkpoint-minutes 10 --hours 1 "$@"
python examples/plot_training.py results/training/p_s_safe --png results/training/p_s_safe/curve.png
cp results/training/p_s_safe/model.zip results/training/p_s_safe.zip
shelf-evaluate --policies results/training/p_s_safe.zip --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb \
    --safe-picks --out results/safe_picks/on
