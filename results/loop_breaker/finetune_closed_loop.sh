#!/usr/bin/env bash
# Fine-tune the shipped P+S model past its training N under issue 13's recommended setting (closed
# loop with the watch's defaults, safe picks): a new run from examples/pretrained/v1/p_s.zip's weights
# (shelf-train --init-from), curriculum N = 9 -> 13 on the training objects with 2000 env steps per
# stage (the 90 % greedy gate is out of reach there, so the cap promotes), 400 H-a demonstration
# steps at N = 9, 11, 13 under the same setting, a quarter of each batch from them, exploration
# from 0.1, greedy checks (10 episodes) every 2500 steps, the actor process; the "p_s" preset
# otherwise. Resumable like train_model.sh (runs/p_s_closed, mirrored to
# results/training/p_s_closed). Then it plays the fine-tuned model with the loop breaker on
# issue 10's YCB grid (N = 3..14, 30 runs, seeds 0 and 1) under the same setting, beside the
# policies of results/loop_breaker/closed_safe (whose cells it reuses), and writes report.md.
# Extra arguments go to shelf-train (e.g. --hours 0.5).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-train --out runs/p_s_closed --mirror results/training/p_s_closed --preset p_s --seed 0 --threads 2 \
    --actor --init-from examples/pretrained/v1/p_s.zip --set safe_picks=true --set closed_loop=true \
    --start-objects 9 --max-objects 13 --max-stage-timesteps 2000 --set exploration_initial_eps=0.1 \
    --set 'demo_objects=[9,11,13]' --set demo_fraction=0.25 --set eval_every=2500 --set eval_episodes=10 \
    --checkpoint-minutes 10 --hours 1.1 "$@"
python examples/plot_training.py results/training/p_s_closed --png results/training/p_s_closed/curve.png
cp results/training/p_s_closed/model.zip results/training/p_s_closed.zip
bash results/loop_breaker/evaluate_closed_safe.sh results/training/p_s_closed.zip results/loop_breaker/closed_safe_finetuned
