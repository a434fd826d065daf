#!/usr/bin/env bash
# P+S fine-tuned under the privileged supervisor (scripts/train_p_s_guard.sh), its last checkpoint
# (results/training/p_s_guard), against the same run without the supervisor (p_s_la), P+S trained
# longer (p_s_long), the shipped P+S, H-d and H-a on issue 10's seed-0 held-out scenes at N = 5, 8, 11
# (30 runs each, YCB objects, greedy, no supervisor): results/p_s_guard. The other policies' cells
# are copied from results/p_s_la (the same scenes). Extra arguments go to shelf-evaluate.
exec bash "$(dirname "$0")/evaluate_run.sh" p_s_guard --policies results/training/p_s_guard.zip \
    results/training/p_s_la.zip results/training/p_s_long.zip examples/pretrained/p_s.zip h-d h-a \
    --reuse-cells results/p_s_la "$@"
