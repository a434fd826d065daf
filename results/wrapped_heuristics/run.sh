#!/usr/bin/env bash
# The heuristics under the shipped policy's camera-only wrappers (docs/experiments/wrapped-heuristics.md): H-d and H-a
# at 1 cm cells, bare and under the shipped geometry filter, pick guard and loop breaker (research.wrapped_heuristics),
# beside the shipped policy, whose cells are copied (by label and digest) from where they were played.
# Usage: bash results/wrapped_heuristics/run.sh val   |   bash results/wrapped_heuristics/run.sh open d|a   |
#   bash results/wrapped_heuristics/run.sh trace   (the risk of the chosen picks, validation scenes at N = 8)   |
#   bash results/wrapped_heuristics/run.sh here d|a   (the shipped policy played again on this machine, its own label)   |
#   bash results/wrapped_heuristics/run.sh push   (H-a with a push fallback under the wrappers: validation scenes)   |
#   bash results/wrapped_heuristics/run.sh pushps   (the shipped policy with the same push rule: validation scenes)   |
#   bash results/wrapped_heuristics/run.sh pushps-open|pushps-closed|pushps-falls   (it, after validation)   |
#   bash results/wrapped_heuristics/run.sh pushps-here   (after pushps-open: its pairs with policies played here)   |
#   bash results/wrapped_heuristics/run.sh strict   (the push rule with the filter at 0.05: validation scenes; it stopped there)
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
export OMP_NUM_THREADS=1
out=results/wrapped_heuristics
shipped="$SHIPPED_GEO$SHIPPED_WRAP"  # the shipped policy and its cells' label: results/heldout.sh
wrap=+shipped-filter+pick-guard+loop-breaker
strict="results/stricter_filter/p_s_geo05.zip+push-fallback$SHIPPED_WRAP"  # the push rule, the filter at 0.05
# the validation scenes (seeds 2000-2002, N = 5, 8, 11, 30 runs) and every policy the steps below play there, in order
val=(--ns 5,8,11 --seeds 3 --runs 30 --first-seed 2000 --object-sets ycb --out $out/val90)
val_policies=("$shipped" h-d-1cm h-a-1cm "h-d-1cm$wrap" "h-a-1cm$wrap" "p_s_geo10_here=$SHIPPED_GEO$SHIPPED_WRAP"
              "h-a-1cm-push$wrap" "$SHIPPED_GEO+push-fallback$SHIPPED_WRAP" "$strict")
# val90's results.csv, results.json and figure over every policy played there so far (each step's own run summarized
# its policies alone; those not played yet have no cells and are left out)
val90_summary() { python -m research.evaluate --policies "${val_policies[@]}" "${val[@]}" --summarize-only; }
step=${1:-val}
if [[ $step == val ]]; then
  # validation: seeds 2000-2002, N = 5, 8, 11, 30 runs; the shipped policy's cells from results/push_guard/val90
  python -m research.evaluate --policies "${val_policies[@]:0:5}" "${val[@]}" --workers "${WORKERS:-1}" \
      --reuse-cells results/push_guard/val90
  val90_summary
  python -m shelf_env.evaluation.compare $out/val90 --pair "$SHIPPED_LABEL" "h-d-1cm$wrap" \
      --pair "$SHIPPED_LABEL" "h-a-1cm$wrap" --pair "h-d-1cm$wrap" h-d-1cm --pair "h-a-1cm$wrap" h-a-1cm \
      --out $out/val90_pairs.md
elif [[ $step == open ]]; then
  # held-out: issue 10's open-loop grid (seeds 0-2, N = 3..14, 30 runs); the others' cells from results/pick_guard/open
  which=${2:?"open needs d, a or push: the wrapped heuristic that sorted more validation scenes, or H-a with pushes"}
  case $which in
    d|a) wrapped="h-$which-1cm$wrap" ;;
    push) wrapped="h-a-1cm-push$wrap" ;;
    *) echo "open needs d, a or push, got '$which'" >&2; exit 2 ;;
  esac
  grid=(--ns 3-14 --runs 30 --seeds 3 --object-sets ycb --out $out/open)
  python -m research.evaluate --policies "$wrapped" "${grid[@]}" --workers "${WORKERS:-1}"
  python -m research.evaluate --policies "$shipped" "${SHIPPED_OTHERS[@]}" "${grid[@]}" \
      --reuse-cells results/pick_guard/open
  python -m research.evaluate --policies "$wrapped" "$shipped" "${SHIPPED_OTHERS[@]}" "${grid[@]}" --summarize-only
  # report_<which>.md, paired_<which>.md: the shipped policy against H-d, H-a and this one; the pairs (with the
  # shipped policy played on this machine too, where run.sh here has played it)
  here=()
  [[ -f $out/open/cells/p_s_geo10_here$SHIPPED_WRAP.sha256 ]] && here=(--pair "p_s_geo10_here$SHIPPED_WRAP" "$wrapped")
  python -m shelf_env.evaluation.report $out/open --learned "$SHIPPED_LABEL" --pick-only s \
      --heuristics h-d h-a "$wrapped" --out $out/open/report_$which.md
  python -m shelf_env.evaluation.compare $out/open --pair "$SHIPPED_LABEL" "$wrapped" "${here[@]}" \
      --pair "$wrapped" h-d --pair "$wrapped" h-a --out $out/open/paired_$which.md
elif [[ $step == push ]]; then
  # H-a with a camera-only push fallback under the wrappers (research.wrapped_heuristics.AccessibilityPushFallback) on
  # the validation scenes, beside the shipped policy played on this machine (p_s_geo10_here)
  python -m research.evaluate --policies "p_s_geo10_here=$SHIPPED_GEO$SHIPPED_WRAP" "h-a-1cm-push$wrap" "${val[@]}" \
      --workers "${WORKERS:-1}"
  val90_summary
  python -m shelf_env.evaluation.compare $out/val90 --pair "h-a-1cm-push$wrap" "h-a-1cm$wrap" \
      --pair "p_s_geo10_here$SHIPPED_WRAP" "h-a-1cm-push$wrap" --pair "p_s_geo10_here$SHIPPED_WRAP" "$SHIPPED_LABEL" \
      --out $out/val90_pairs_push.md
elif [[ $step == pushps ]]; then
  # the shipped policy with the same push rule innermost (+push-fallback) on the validation scenes, paired with the
  # shipped policy played here (p_s_geo10_here, run.sh push)
  python -m research.evaluate --policies "$SHIPPED_GEO+push-fallback$SHIPPED_WRAP" "${val[@]}" --workers "${WORKERS:-1}"
  val90_summary
  python -m shelf_env.evaluation.compare $out/val90 --pair "p_s_geo10+push-fallback$SHIPPED_WRAP" \
      "p_s_geo10_here$SHIPPED_WRAP" --pair "p_s_geo10+push-fallback$SHIPPED_WRAP" "h-a-1cm-push$wrap" \
      --out $out/val90_pairs_pushps.md
elif [[ $step == pushps-open || $step == pushps-closed || $step == pushps-falls ]]; then
  # the shipped policy with the push rule, after validation: issue 10's open-loop grid, closed loop + safe picks, the
  # greedy fall rate at N = 8 (results/heldout.sh's after_validation) -> $out/pushps/
  after_validation "${step#pushps-}" $out/pushps "$SHIPPED_GEO+push-fallback$SHIPPED_WRAP" \
      "p_s_geo10+push-fallback$SHIPPED_WRAP" "$SHIPPED_LABEL" $SHIPPED_REF research.wrapped_heuristics "$shipped" \
      "${SHIPPED_OTHERS[@]}"
elif [[ $step == pushps-here ]]; then
  # after pushps-open: the same-machine pairs. The shipped policy played on this machine (run.sh here) and H-a with the
  # push rule (run.sh open push), their cells copied from $out/open into $out/pushps/open
  grid=(--ns 3-14 --runs 30 --seeds 3 --object-sets ycb --out $out/pushps/open)
  python -m research.evaluate --policies "p_s_geo10_here=$SHIPPED_GEO$SHIPPED_WRAP" "h-a-1cm-push$wrap" "${grid[@]}" \
      --reuse-cells $out/open
  # results.csv, results.json and the figure back to pushps-open's policies (the copy above summarized its own two)
  python -m research.evaluate --policies "$SHIPPED_GEO+push-fallback$SHIPPED_WRAP" "$shipped" "${SHIPPED_OTHERS[@]}" \
      "${grid[@]}" --summarize-only
  python -m shelf_env.evaluation.compare $out/pushps/open --pair "p_s_geo10+push-fallback$SHIPPED_WRAP" \
      "p_s_geo10_here$SHIPPED_WRAP" --pair "p_s_geo10+push-fallback$SHIPPED_WRAP" "h-a-1cm-push$wrap" \
      --out $out/pushps/open/paired_here.md
elif [[ $step == strict ]]; then
  # the push rule with the stricter filter (the shipped fall model at 0.05: results/stricter_filter) on the validation
  # scenes, paired with the push rule at 0.1 and the shipped policy, both played here
  python -m research.evaluate --policies "$strict" "${val[@]}" --workers "${WORKERS:-1}"
  val90_summary
  python -m shelf_env.evaluation.compare $out/val90 --pair "p_s_geo05+push-fallback$SHIPPED_WRAP" \
      "p_s_geo10+push-fallback$SHIPPED_WRAP" --pair "p_s_geo05+push-fallback$SHIPPED_WRAP" \
      "p_s_geo10_here$SHIPPED_WRAP" --out $out/val90_pairs_strict.md
elif [[ $step == here ]]; then
  # the shipped policy's held-out cells were played on another machine (PyBullet's floating point differs between
  # CPUs): play them again here under the label p_s_geo10_here..., paired with the wrapped heuristic played here
  which=${2:?"here needs d or a: the wrapped heuristic of run.sh open"}
  [[ $which == d || $which == a ]] || { echo "here needs d or a, got '$which'" >&2; exit 2; }
  here="p_s_geo10_here=$SHIPPED_GEO$SHIPPED_WRAP"
  grid=(--ns 3-14 --runs 30 --seeds 3 --object-sets ycb --out $out/open)
  python -m research.evaluate --policies "$here" "${grid[@]}" --workers "${WORKERS:-1}"
  python -m shelf_env.evaluation.compare $out/open --pair "p_s_geo10_here$SHIPPED_WRAP" "h-$which-1cm$wrap" \
      --pair "p_s_geo10_here$SHIPPED_WRAP" "$SHIPPED_LABEL" --out $out/open/paired_here.md
elif [[ $step == trace ]]; then
  # a diagnostic that changes no action (+risk-trace, outermost): how often the chosen pick is one the shipped risk
  # calls risky, on the validation scenes at N = 8 (outcomes checked against val90)
  python -m research.evaluate --policies "$shipped+risk-trace" "h-a-1cm$wrap+risk-trace" h-a-1cm+risk-trace --ns 8 \
      --seeds 3 --runs 30 --first-seed 2000 --object-sets ycb --workers "${WORKERS:-1}" --out $out/trace_n8
  python -m research.wrapped_heuristics $out/trace_n8 $out/val90 --out $out/trace_n8.md
else
  echo "usage: run.sh val | open d|a|push | here d|a | push | pushps | pushps-open|closed|falls | pushps-here | strict | trace" >&2
  exit 2
fi
