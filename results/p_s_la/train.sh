#!/usr/bin/env bash
# P+S fine-tuned at N = 8 with the privileged lookahead teacher: the weights of P+S trained longer
# (results/training/p_s_long.zip, results/p_s_long/train.sh) trained on at N = 8 with demonstrations
# of H-d with the one-step simulator lookahead (shelf_env.privileged.lookahead, h-d-lookahead: no falls on
# issue 10's scenes at N = 5, 8, 11) at N = 5, 8 and 11 instead of H-a's at N = 3, and the picks
# that teacher rejected (its probe saw them drop an object) kept as terminal transitions of the same
# state (demo_counterfactuals, TD loss only), into results/training/p_s_la (committed; running this again resumes, a fresh machine from that copy).
# The demonstrations are collected on an in-process env first (their wall time counts); then the
# actor process steps the env while the learner trains (two CPU cores). Extra arguments go to
# shelf-train (e.g. --hours, the total wall clock). The committed run was started with the preset's
# stage cap (5000 env steps, which ends a run at its last stage) and resumed with
# `--amend max_stage_timesteps=40000 --hours 1.3` (progress.json's amendments); a new run sets it.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-train --out runs/p_s_la --mirror results/training/p_s_la --preset p_s --seed 0 \
    --init-from results/training/p_s_long.zip --start-objects 8 --max-objects 8 \
    --set demo_policy=h-d-lookahead --set 'demo_objects=[5,8,11]' --set demo_steps=750 --set demo_counterfactuals=true \
    --set eval_every=4000 --set max_stage_timesteps=40000 \
    --actor --hours 1.4 --threads 2 --checkpoint-minutes 10 "$@"
python examples/plot_training.py results/training/p_s_la --png results/training/p_s_la/curve.png
