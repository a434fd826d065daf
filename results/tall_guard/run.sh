#!/usr/bin/env bash
# Carries blocked by objects taller than any training object (docs/experiments/tall-guard.md): candidate
# research.tall_guard innermost under the shipped wrappers on the validation scenes, and on issue 10's held-out scenes
# if it passes there. The shipped policy's cells are copied (by label and digest) from where they were played.
# Usage: bash results/tall_guard/run.sh val   |   bash results/tall_guard/run.sh open|closed|falls
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
export OMP_NUM_THREADS=1
out=results/tall_guard
shipped="$SHIPPED_GEO$SHIPPED_WRAP"  # the shipped policy and its cells' label: results/heldout.sh
candidate="$SHIPPED_GEO+tall-guard$SHIPPED_WRAP"
new=p_s_geo10+tall-guard$SHIPPED_WRAP
step=${1:-val}
if [[ $step == val ]]; then
  # validation: seeds 2000-2002, N = 5, 8, 11; the shipped policy's cells from results/push_guard/val90
  validate $out "$candidate" "$new" "$SHIPPED_LABEL" results/push_guard/val90 "$shipped"
fi
if [[ $step == open || $step == closed || $step == falls ]]; then
  # held-out: the open-loop grid, closed loop + safe picks, the greedy fall rate at N = 8 (results/heldout.sh)
  after_validation "$step" $out "$candidate" "$new" "$SHIPPED_LABEL" $SHIPPED_REF research.tall_guard "$shipped" \
      "${SHIPPED_OTHERS[@]}"
fi
