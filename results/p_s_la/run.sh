#!/usr/bin/env bash
# P+S fine-tuned with the lookahead teacher and its counterfactuals (results/p_s_la/train.sh), its
# last checkpoint (results/training/p_s_la) and its step-5000 one (results/training/
# p_s_la_step5000.zip: the run's checkpoint when the preset's 5000-step stage cap first ended it;
# `results/p_s_la/train.sh --max-steps 5000` stops a new run there), against P+S trained longer
# (p_s_long), the shipped P+S, H-d and H-a on issue 10's seed-0 held-out scenes at N = 5, 8, 11
# (30 runs each, YCB objects): results/p_s_la. The other policies' cells are copied from
# results/p_s_long (the same scenes). Extra arguments go to shelf-evaluate.
exec bash "$(dirname "$0")/../../research/evaluate_run.sh" p_s_la --policies results/training/p_s_la.zip \
    results/training/p_s_la_step5000.zip results/training/p_s_long.zip examples/pretrained/v1/p_s.zip h-d h-a \
    --reuse-cells results/p_s_long "$@"
