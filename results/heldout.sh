# The held-out step shared by the experiments' run.sh (sourced, not run): a candidate policy that passed validation,
# played on issue 10's held-out scenes beside the shipped policy and the baselines, whose cells are copied from an
# earlier evaluation folder (--reuse-cells checks them by label and, for checkpoints, by file digest). Run from the
# repository root; WORKERS (default 1) processes play the candidate's cells.
#   heldout open|closed OUT CANDIDATE NEW OLD REF REUSE SHIPPED [OTHER...]
# open: open loop, seeds 0-2, N = 3..14, 30 runs (1,080 scenes per policy) into OUT/open, its report.md against S,
# H-d and H-a; closed: closed loop + safe picks, seed 0, N = 3..14, 30 runs (360 scenes per policy) into
# OUT/closed_safe, its report against H-d and H-a.
# OUT: the experiment's results folder; CANDIDATE: the policy played; NEW, OLD, REF: the cells' labels of the
# candidate, the shipped policy and the shipped Q-maps alone (the pairs in paired.md); REUSE: the folder the other
# policies' cells are copied from; SHIPPED and OTHER: those policies.
heldout() {
  local mode=$1 out=$2 candidate=$3 new=$4 old=$5 ref=$6 reuse=$7 shipped=$8
  shift 8
  local folder grid pick_only=()
  case $mode in
    open)
      folder=$out/open
      grid=(--ns 3-14 --runs 30 --seeds 3 --object-sets ycb --out "$folder")
      pick_only=(--pick-only s) ;;
    closed)
      folder=$out/closed_safe
      grid=(--ns 3-14 --runs 30 --seeds 1 --object-sets ycb --closed-loop '{}' --safe-picks --out "$folder") ;;
    *)
      echo "heldout: the mode is open or closed, got '$mode'" >&2
      return 2 ;;
  esac
  python -m research.evaluate --policies "$candidate" "${grid[@]}" --workers "${WORKERS:-1}"
  python -m research.evaluate --policies "$shipped" "$@" "${grid[@]}" --reuse-cells "$reuse"
  python -m research.evaluate --policies "$candidate" "$shipped" "$@" "${grid[@]}" --summarize-only
  python -m shelf_env.evaluation.report "$folder" --learned "$new" "${pick_only[@]}" --heuristics h-d h-a
  python -m shelf_env.evaluation.compare "$folder" --pair "$new" "$old" --pair "$new" "$ref" --pair "$new" h-d \
      --pair "$new" h-a --out "$folder/paired.md"
}
