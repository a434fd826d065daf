#!/usr/bin/env bash
# P+S trained longer at N = 8 (results/p_s_long/train.sh) against the shipped P+S, H-d and H-a on
# issue 10's seed-0 held-out scenes at N = 5, 8, 11 (30 runs each, YCB objects): results/p_s_long.
# Extra arguments go to shelf-evaluate (research/evaluate_run.sh).
exec bash "$(dirname "$0")/../../research/evaluate_run.sh" p_s_long "$@"
