#!/usr/bin/env bash
# P+S fine-tuned at N = 8 under the privileged supervisor (TrainConfig.guard, shelf_env.privileged.lookahead.FallGuard):
# results/p_s_la/train.sh's run (p_s_long's weights, h-d-lookahead demonstrations at N = 5, 8, 11
# with the teacher's counterfactuals) plus, on every training step, the learner's own (ε-greedy)
# action tried in a forked copy of the simulator first; one that would drop an object is replaced by
# the teacher's choice and both kept (the vetoed action as a terminal transition, TD loss only; the
# teacher's as a demonstration): DAgger-style corrections where the learner's policy goes. Into
# results/training/p_s_guard (committed; running this again resumes, a fresh machine from that copy).
# Greedy checks and evaluations act without the supervisor. Extra arguments go to shelf-train
# (e.g. --hours, the total wall clock, or --set for a variant); RUN=NAME (default p_s_guard) names
# the run folder, runs/NAME mirrored to results/training/NAME.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
run=${RUN:-p_s_guard}
shelf-train --out "runs/$run" --mirror "results/training/$run" --preset p_s --seed 0 \
    --init-from results/training/p_s_long.zip --start-objects 8 --max-objects 8 \
    --set demo_policy=h-d-lookahead --set 'demo_objects=[5,8,11]' --set demo_steps=750 --set demo_counterfactuals=true \
    --set guard=h-d-lookahead --set eval_every=2500 --set max_stage_timesteps=40000 \
    --actor --hours 1.0 --threads 2 --checkpoint-minutes 10 "$@"
python examples/plot_training.py "results/training/$run" --png "results/training/$run/curve.png"
