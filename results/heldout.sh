# The steps shared by the experiments' run.sh (sourced, not run): `geometry_refit`, `validate`, `after_validation`
# (below) and `heldout`: a candidate policy that passed validation,
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
# The shipped policy as the validation and held-out cells label it (its Q-maps with its geometry risk, p_s_geo10, under
# its wrappers), the shipped Q-maps alone, and the other policies issue 10's grid compares with: for a candidate that
# wraps the shipped policy (`$SHIPPED_GEO+<its wrapper>$SHIPPED_WRAP`).
SHIPPED_GEO=results/fall_geometry/filter/p_s_geo10.zip
SHIPPED_WRAP=+geometry-filter+pick-guard+loop-breaker
SHIPPED_LABEL=p_s_geo10$SHIPPED_WRAP
SHIPPED_REF=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # results/models_v3
SHIPPED_OTHERS=("$SHIPPED_REF=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)

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

# validate OUT CANDIDATE NEW OLD REUSE SHIPPED: the candidate on the validation scenes (seeds 2000-2002, N = 5, 8, 11,
# 30 runs: 270 scenes, open loop) beside the shipped policy, whose cells are copied from REUSE -> OUT/val90 and its
# pairs NEW against OLD in OUT/val90_pairs.md.
validate() {
  local out=$1 candidate=$2 new=$3 old=$4 reuse=$5 shipped=$6
  python -m research.evaluate --policies "$shipped" "$candidate" --ns 5,8,11 --seeds 3 --runs 30 --first-seed 2000 \
      --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" --reuse-cells "$reuse"
  python -m shelf_env.evaluation.compare "$out/val90" --pair "$new" "$old" --out "$out/val90_pairs.md"
}

# after_validation STEP OUT CANDIDATE NEW OLD REF MODULE SHIPPED [OTHER...]: a candidate that passed validation on
# issue 10's held-out scenes. open: the open-loop grid beside SHIPPED and OTHER (their cells from
# results/pick_guard/open); closed: closed loop + safe picks beside SHIPPED, the shipped Q-maps alone, H-d and H-a
# (from results/pick_guard/closed_safe); falls: its greedy fall rate per decision at N = 8 on the first 30 held-out
# scenes of seed 0 (shelf_env.evaluation.falls with MODULE imported, which registers the candidate's wrapper;
# resumable) -> OUT/falls30.json.
after_validation() {
  local step=$1 out=$2 candidate=$3 new=$4 old=$5 ref=$6 module=$7 shipped=$8
  shift 8
  case $step in
    open) heldout open "$out" "$candidate" "$new" "$old" "$ref" results/pick_guard/open "$shipped" "$@" ;;
    closed) heldout closed "$out" "$candidate" "$new" "$old" "$ref" results/pick_guard/closed_safe "$shipped" \
        "$ref=examples/pretrained/p_s.zip" h-d h-a ;;
    falls) python -c "import $module, sys; from shelf_env.evaluation.falls import main; sys.exit(main(sys.argv[1:]))" \
        "$candidate" --ns 8 --runs 30 --seed 0 --out "$out/falls30.json" ;;
    *)
      echo "after_validation: the step is open, closed or falls, got '$step'" >&2
      return 2 ;;
  esac
}

# geometry_refit STEP OUT NAME SPLIT...: round two's geometry fall-model recipe on the split SPLIT (research.fall_geometry
# options: --data, --max-shards, --fresh, ...). features: the 36 features with the blocker features -> OUT/features.npz;
# fit: the MLP and logistic regression beside the shipped risk (examples/pretrained/p_s.geometry_risk.pt) ->
# OUT/fit.json, OUT/fit.models.pt; export: the shipped p_s.zip copied to OUT/NAME.zip and the fit's MLP at the shipped
# threshold 0.1 -> OUT/NAME.geometry_risk.pt (a filter for it). Each step skips a file already on disk; "all" runs
# the three.
geometry_refit() {
  local step=$1 out=$2 name=$3
  shift 3
  if [[ $step == features || $step == all ]]; then
    [ -f "$out/features.npz" ] || python -m research.fall_geometry features "$@" --blockers --out "$out/features.npz"
  fi
  if [[ $step == fit || $step == all ]]; then
    [ -f "$out/fit.json" ] || python -m research.fall_geometry fit "$@" --features "$out/features.npz" \
        --compare examples/pretrained/p_s.geometry_risk.pt --out "$out/fit.json"
  fi
  if [[ $step == export || $step == all ]]; then
    cp -p examples/pretrained/p_s.zip "$out/$name.zip"
    [ -f "$out/$name.geometry_risk.pt" ] || python -m research.fall_geometry export --models "$out/fit.models.pt" \
        --name mlp --features "$out/features.npz" --threshold 0.1 --out "$out/$name.geometry_risk.pt"
  fi
}
