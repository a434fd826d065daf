#!/usr/bin/env bash
# The push guard (docs/experiments/push-guard.md): the shipped P+S with and without a guard against wasted pushes
# (research.push_guard), innermost under its filter, pick guard and loop breaker. First what the shipped policy's
# greedy pushes did in series 5 of the teacher dataset (training scenes); then candidates P (+push-guard: no pushes
# into objects that look sorted) and Q (+pick-first: no pushes while a pick is allowed) on the validation scenes;
# then the candidate the page's rule picks on issue 10's held-out scenes: the open-loop grid, closed loop + safe
# picks, its greedy fall rate at N = 8. The shipped policy's cells are copied (by label and digest) from where they
# were played. Added after the first validation (the page's second round): candidate R, P under the stricter filter
# (threshold 0.05: results/stricter_filter/p_s_geo05), on the same validation scenes (val2).
# Usage: bash results/push_guard/run.sh [stats|val|val2|all]   |   bash results/push_guard/run.sh open|closed|falls p|q|r
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
out=results/push_guard
geo=results/fall_geometry/filter/p_s_geo10.zip  # the shipped p_s.zip + its geometry risk, the label they were played as
wrap=+geometry-filter+pick-guard+loop-breaker
shipped="$geo$wrap"
old=p_s_geo10$wrap  # the shipped policy's cells' label
p="$geo+push-guard$wrap"  # candidate P
q="$geo+pick-first$wrap"  # candidate Q
r="results/stricter_filter/p_s_geo05.zip+push-guard$wrap"  # candidate R: P under the filter at 0.05
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
step=${1:-all}
if [[ $step == stats || $step == all ]]; then
  python -m research.push_guard stats data/teacher --series s05 --out $out/series5.md
fi
if [[ $step == val || $step == all ]]; then
  # 1. validation: seeds 2000-2002, N = 5, 8, 11; the shipped policy's cells from results/stricter_filter/val90
  python -m research.evaluate --policies "$shipped" "$p" "$q" --ns 5,8,11 --seeds 3 --runs 30 --first-seed 2000 \
      --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" --reuse-cells results/stricter_filter/val90
  for c in push-guard pick-first; do
    python -m shelf_env.evaluation.compare "$out/val90" --pair "p_s_geo10+$c$wrap" $old \
        --out "$out/val90_pairs_$c.md"
  done
fi
if [[ $step == val2 || $step == all ]]; then
  # the second round: R on the same scenes (P, Q and the shipped policy's cells are already in val90)
  python -m research.evaluate --policies "$shipped" "$p" "$q" "$r" --ns 5,8,11 --seeds 3 --runs 30 --first-seed 2000 \
      --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90"
  python -m shelf_env.evaluation.compare "$out/val90" --pair "p_s_geo05+push-guard$wrap" $old \
      --out "$out/val90_pairs_geo05_push-guard.md"
  python -m shelf_env.evaluation.compare "$out/val90" --pair "p_s_geo05+push-guard$wrap" "p_s_geo10+push-guard$wrap" \
      --out "$out/val90_pairs_geo05_vs_geo10.md"
fi
if [[ $step == open || $step == closed || $step == falls ]]; then
  case ${2:-} in
    p) candidate=$p; new=p_s_geo10+push-guard$wrap ;;
    q) candidate=$q; new=p_s_geo10+pick-first$wrap ;;
    r) candidate=$r; new=p_s_geo05+push-guard$wrap ;;
    *) echo "run.sh $step: name the candidate that passed validation, p, q or r" >&2; exit 2 ;;
  esac
  # 2-4. held-out (results/heldout.sh): the open-loop grid (seeds 0-2, N = 3..14; every policy but the candidate
  # copied), closed loop + safe picks (seed 0, N = 3..14), and the candidate's greedy fall rate per decision at N = 8
  # on the first 30 held-out scenes of seed 0 (resumable)
  after_validation "$step" $out "$candidate" "$new" $old $ref research.push_guard "$shipped" "${others[@]}"
fi
