#!/usr/bin/env bash
# The planning teacher (h-d-planner; docs/experiments/teacher-dataset.md) on the §V comparison's own scenes
# (seed 0, YCB, open loop): its cost per decision, the first 10 scenes at N = 3..11 and the first 3 at N = 12,
# 13 and 14 (10-20 min an episode there on one core), then each N's scenes sorted beside every policy that played
# the same scenes (results/distill_test: H-d, H-a and their loop-breaker variants, P+S, S at N = 5, 8, 11;
# results/privileged_ceiling_open: the one-step lookahead and the others at every N; results/models) and the
# planner's margin over the better of H-d and H-a per N, averaged over the N measured.
# Resumable cell by cell (one N per call, so that a stopped run keeps the N it finished).
#   bash results/planning_teacher/run.sh [N ...]        # 10 scenes each; default: 3 4 5 6 7 8 9 10 11
#   bash results/planning_teacher/run.sh closed_safe [N ...]   # closed loop (the watch's defaults) + safe picks,
#       the first 10 scenes of seed 0 at each N (default: 5 8 3 4 6 7), beside the policies that played them under
#       the same conditions (results/privileged_ceiling: H-d, H-a, their loop-breaker variants, the one-step
#       lookahead + LB, the shipped P+S + LB) -> results/planning_teacher/closed_safe/ (report.md)
#   bash results/planning_teacher/run.sh closed_safe large [N ...]   # the same, the first 3 scenes at each N
#       (default: 12 13 14, as the open loop there)
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1
out=results/planning_teacher
planner() { .venv/bin/shelf-evaluate --policies h-d-planner --seeds 1 --object-sets ycb "$@"; }
each_n() {  # NS OPTIONS...: one planner call per N of NS (a stopped run keeps every N it finished)
  local ns=$1
  shift
  for k in $ns; do
    planner --ns "$k" --workers 1 "$@"
  done
}
if [ "${1:-}" = closed_safe ]; then
  shift
  out=$out/closed_safe
  cond=(--closed-loop '{}' --safe-picks --out $out)
  if [ "${1:-}" = large ]; then  # the first 3 scenes per N, as the open loop at N = 12..14
    shift
    each_n "${*:-12 13 14}" --runs 3 "${cond[@]}"
  else
    each_n "${*:-5 8 3 4 6 7}" --runs 10 "${cond[@]}"
  fi
  # results.json / results.csv / the plot: the 10-scene cells (the 3-scene ones are in report.md)
  ns=$(ls $out/cells | sed -n "s/.*__N0*\([0-9][0-9]*\)__.*__runs10\.json/\1/p" | sort -n | paste -sd, -)
  planner --ns "$ns" --runs 10 "${cond[@]}" --summarize-only
  .venv/bin/python research/planner_probe.py $out --against results/privileged_ceiling --out $out/report.md \
    --policies h-d h-a h-d+loop-breaker h-a+loop-breaker h-d-lookahead+loop-breaker p_s+loop-breaker
  exit 0
fi
[ -f $out/teacher_cost.txt ] || .venv/bin/python benchmarks/teacher_cost.py --ns 3 5 8 13 --scenes 2 --decisions 3 \
  > $out/teacher_cost.txt
each_n "${*:-3 4 5 6 7 8 9 10 11}" --runs 10 --out $out
each_n "12 13 14" --runs 3 --out $out
# results.json / results.csv / the plot: every 10-scene cell on disk (each call above wrote its own N only)
planner --ns 3-11 --runs 10 --out $out --summarize-only
.venv/bin/python research/planner_probe.py $out --against results/distill_test results/privileged_ceiling_open \
  results/models --out $out/report.md \
  --policies h-d h-a h-d+loop-breaker h-a+loop-breaker h-d-lookahead+loop-breaker p_s s
