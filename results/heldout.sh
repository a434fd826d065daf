# Held-out steps shared by the experiments' run.sh (sourced, not run): a candidate policy that passed validation,
# played on issue 10's held-out scenes beside the shipped policy and the baselines, whose cells are copied from an
# earlier evaluation folder (--reuse-cells checks them by label and, for checkpoints, by file digest). Run from the
# repository root; WORKERS (default 1) processes play the candidate's cells.
#   heldout_open OUT CANDIDATE NEW OLD REF REUSE SHIPPED [OTHER...]
#   heldout_closed OUT CANDIDATE NEW OLD REF REUSE SHIPPED [OTHER...]
# OUT: the experiment's results folder (open/ or closed_safe/ inside it); CANDIDATE: the policy played; NEW, OLD, REF:
# the cells' labels of the candidate, the shipped policy and the shipped Q-maps alone (the pairs in paired.md);
# REUSE: the folder the other policies' cells are copied from; SHIPPED and OTHER: those policies.

# open loop: seeds 0-2, N = 3..14, 30 runs (1,080 scenes per policy); report.md against S, H-d and H-a
heldout_open() {
  local out=$1 candidate=$2 new=$3 old=$4 ref=$5 reuse=$6 shipped=$7
  shift 7
  local grid=(--ns 3-14 --runs 30 --seeds 3 --object-sets ycb --out "$out/open")
  python -m research.evaluate --policies "$candidate" "${grid[@]}" --workers "${WORKERS:-1}"
  python -m research.evaluate --policies "$shipped" "$@" "${grid[@]}" --reuse-cells "$reuse"
  python -m research.evaluate --policies "$candidate" "$shipped" "$@" "${grid[@]}" --summarize-only
  python -m shelf_env.evaluation.report "$out/open" --learned "$new" --pick-only s --heuristics h-d h-a
  python -m shelf_env.evaluation.compare "$out/open" --pair "$new" "$old" --pair "$new" "$ref" --pair "$new" h-d \
      --pair "$new" h-a --out "$out/open/paired.md"
}

# closed loop + safe picks: seed 0, N = 3..14, 30 runs (360 scenes per policy)
heldout_closed() {
  local out=$1 candidate=$2 new=$3 old=$4 ref=$5 reuse=$6 shipped=$7
  shift 7
  local grid=(--ns 3-14 --runs 30 --seeds 1 --object-sets ycb --closed-loop '{}' --safe-picks --out "$out/closed_safe")
  python -m research.evaluate --policies "$candidate" "${grid[@]}" --workers "${WORKERS:-1}"
  python -m research.evaluate --policies "$shipped" "$@" "${grid[@]}" --reuse-cells "$reuse"
  python -m research.evaluate --policies "$candidate" "$shipped" "$@" "${grid[@]}" --summarize-only
  python -m shelf_env.evaluation.report "$out/closed_safe" --learned "$new" --heuristics h-d h-a
  python -m shelf_env.evaluation.compare "$out/closed_safe" --pair "$new" "$old" --pair "$new" "$ref" \
      --pair "$new" h-d --pair "$new" h-a --out "$out/closed_safe/paired.md"
}
