#!/usr/bin/env bash
# New Q-maps under the shipped wrappers (docs/experiments/own-states.md): candidate A, the scaling curve's eleventh
# point (averaged weights); candidate B, the shipped p_s.zip fine-tuned on series 5 (the teacher's labels of the
# shipped policy's own states); both played under the shipped geometry filter (its risk model copied beside each),
# the pick guard and the loop breaker on the 270 validation scenes. The shipped policy's cells are copied (by label
# and digest) from results/stricter_filter/val90.
# Then (added after the validation, as the plan says) the candidate that passed it, A, on issue 10's held-out scenes:
# the open-loop grid, then closed loop + safe picks, every other policy's cells copied from results/pick_guard.
# The twenty-first session: candidate C, A fine-tuned for 2 epochs on every shard complete at its start, on the same
# validation scenes (the other policies' cells are already in val90): steps c and valc.
# The twenty-second session: candidate D, C without series 5 (steps d and vald).
# The twenty-sixth session: candidate E, the scaling curve's twelfth point (averaged weights), as A was (e, vale).
# The twenty-seventh session: candidate F, the twelfth point's seed-1 replicate (averaged weights), as E (f, valf);
# candidate G, the eleventh point with a set target for the teacher term (docs/experiments/teacher-set.md; g, valg).
# The twenty-eighth session: candidate H, the twelfth point's seed-2 replicate (averaged weights), as F (h, valh).
# Usage: bash results/own_states/run.sh [a|b|val|open|closed|falls|c|valc|d|vald|e|vale|f|valf|g|valg|h|valh|all|
#   openc|closedc|fallsc|opend|closedd|fallsd|opene|closede|fallse|openf|closedf|fallsf|openg|closedg|fallsg|openh|
#   closedh|fallsh|series]
#   (WORKERS=2 for two processes)
set -euo pipefail
cd "$(dirname "$0")/../.."
. results/heldout.sh
out=results/own_states
M=runs/distill_scaling
risk=results/fall_geometry/filter/p_s_geo10.geometry_risk.pt  # the shipped filter's risk model (threshold 0.1)
shipped=results/fall_geometry/filter/p_s_geo10.zip+geometry-filter+pick-guard+loop-breaker
old=p_s_geo10+geometry-filter+pick-guard+loop-breaker  # the shipped policy's cells' label
wrap=+geometry-filter+pick-guard+loop-breaker
a=p_s_dagger594_aug_mpa_r2_ce1_avg4  # candidate A
b=p_s_own5  # candidate B
S05=s05:22  # every series-5 shard complete when B's run started (17:44, twentieth session)
step=${1:-all}
point() {  # point NAME [SCRIPT]: a model copied here from its run (SCRIPT, default the scaling curve's, trains it
  local m=$1  # first if missing), its risk model beside it
  if [ ! -f "$out/$m.zip" ]; then
    [ -f "$M/$m.zip" ] || bash "${2:-results/distill_scaling/run.sh}"
    cp -p "$M/$m.zip" "$M/$m.distill.json" "$out/"
  fi
  cp -p "$risk" "$out/$m.geometry_risk.pt"
}
if [[ $step == a || $step == all ]]; then
  point $a
fi
if [[ $step == b || $step == all ]]; then
  [ -f "$out/$b.zip" ] || OMP_NUM_THREADS=2 python -m shelf_env.training.distill --data data/teacher \
      --max-shards "$S05" --init examples/pretrained/p_s.zip --out "$out/$b.zip" --epochs 8 --val-fraction 0.2 \
      --anchor 1.0 --teacher-radius 2 --teacher-temperature 1 --average-last 4 2>&1 | tee "$out/$b.log"
  cp -p "$risk" "$out/$b.geometry_risk.pt"
fi
finetune() {  # finetune NAME SHARDS: A's weights trained 2 more epochs on SHARDS (--max-shards), the mean of both
  local m=$1 shards=$2
  [ -f "$out/$m.zip" ] || OMP_NUM_THREADS=2 python -m shelf_env.training.distill --data data/teacher \
      --max-shards "$shards" --init "$out/$a.zip" --out "$out/$m.zip" --epochs 2 --val-fraction 0.2 \
      --anchor 1.0 --teacher-radius 2 --teacher-temperature 1 --average-last 2 \
      --resume-file "$out/$m.resume.pt" 2>&1 | tee -a "$out/$m.log"
  cp -p "$risk" "$out/$m.geometry_risk.pt"
}
c=p_s_all772  # candidate C
SC=s00:55,s01:50,s02:205,s03:246,s04:172,s05:44  # every shard complete when C's run started (twenty-first session)
if [[ $step == c || $step == all ]]; then
  finetune $c "$SC"
fi
d=p_s_all_s0to4  # candidate D: C's recipe and shards without series 5 (the twenty-second session)
SD=s00:55,s01:50,s02:205,s03:246,s04:172
if [[ $step == d || $step == all ]]; then
  finetune $d "$SD"
fi
e=p_s_dagger1383_aug_mpa_r2_ce1_avg4  # candidate E: the scaling curve's twelfth point, averaged (twenty-sixth session)
if [[ $step == e || $step == all ]]; then
  point $e
fi
f=p_s_dagger1383_aug_mpa_r2_ce1_seed1_avg4  # candidate F: the twelfth point's seed-1 replicate, averaged (27th session)
if [[ $step == f || $step == all ]]; then
  point $f
fi
g=p_s_dagger594_aug_mpa_r2_ce1_set_avg4  # candidate G: A's run with --teacher-set (twenty-seventh session)
if [[ $step == g || $step == all ]]; then
  point $g results/teacher_set/run.sh
fi
h=p_s_dagger1383_aug_mpa_r2_ce1_seed2_avg4  # candidate H: the twelfth point's seed-2 replicate, averaged (28th session)
if [[ $step == h || $step == all ]]; then
  point $h
fi
# Validation: seeds 2000-2002, N = 5, 8, 11. Each validation step (and all, once) evaluates every candidate in one
# list (cells already played are kept, the shipped policy's copied from results/stricter_filter/val90), so that
# val90's summary holds them all whichever step ran last; each step then writes its own candidate's pairs. A
# candidate not made yet (its zip not here: F before its run ends) is left out until it is.
if [[ $step == val || $step == valc || $step == vald || $step == vale || $step == valf || $step == valg ||
    $step == valh || $step == all ]]; then
  made=()
  for m in $a $b $c $d $e $f $g $h; do
    [ -f "$out/$m.zip" ] && made+=("$out/$m.zip$wrap")
  done
  python -m research.evaluate --policies "$shipped" "${made[@]}" --ns 5,8,11 --seeds 3 --runs 30 --first-seed 2000 \
      --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" --reuse-cells results/stricter_filter/val90
fi
pairs() {  # pairs NAME AGAINST...: NAME (wrapped) against each label on the validation scenes
  local m=$1
  shift
  for o in "$@"; do
    python -m shelf_env.evaluation.compare "$out/val90" --pair "$m$wrap" "$o" --out "$out/val90_pairs_${m}_vs_${o%%+*}.md"
  done
}
if [[ $step == val || $step == all ]]; then
  for m in $a $b; do
    python -m shelf_env.evaluation.compare "$out/val90" --pair "$m$wrap" $old --out "$out/val90_pairs_$m.md"
  done
fi
if [[ $step == valc || $step == all ]]; then
  pairs $c $old $a$wrap
fi
if [[ $step == vald || $step == all ]]; then
  pairs $d $old $a$wrap $c$wrap
fi
if [[ $step == vale || $step == all ]]; then
  pairs $e $old $a$wrap
fi
if [[ $step == valf || $step == all ]]; then
  pairs $f $old $a$wrap $e$wrap
fi
if [[ $step == valg || $step == all ]]; then
  pairs $g $old $a$wrap
fi
if [[ $step == valh || $step == all ]]; then
  pairs $h $old $a$wrap $e$wrap $f$wrap
fi
candidate="$out/$a.zip$wrap"  # the candidate that passed validation
new=$a$wrap  # its cells' label
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4  # the shipped Q-maps alone (results/models_v3)
others=("$ref=examples/pretrained/p_s.zip" examples/pretrained/s.zip h-d h-a)
if [[ $step == open || $step == all ]]; then
  # held-out, open loop: issue 10's grid (seeds 0-2, N = 3..14); every policy but the candidate copied
  heldout open $out "$candidate" $new $old $ref results/pick_guard/open "$shipped" "${others[@]}"
fi
if [[ $step == closed || $step == all ]]; then
  # held-out, closed loop + safe picks: seed 0, N = 3..14
  heldout closed $out "$candidate" $new $old $ref results/pick_guard/closed_safe "$shipped" \
      "$ref=examples/pretrained/p_s.zip" h-d h-a
fi
if [[ $step == falls || $step == all ]]; then
  # the candidate's greedy fall rate per decision at N = 8, the first 30 held-out scenes of seed 0 (resumable)
  python -m shelf_env.evaluation.falls "$candidate" --ns 8 --runs 30 --seed 0 --out "$out/falls30.json"
fi
# Candidates C to H on the held-out scenes, only where they passed validation (the page's rules; not part of
# "all"): each in its own folder ($out/c ... $out/h), every other policy's cells (A's too) copied from this
# folder's open/ and closed_safe/; the candidate against A too.
held() {  # held open|closed|falls NAME DIR
  local mode=$1 m=$2 dir=$3
  case $mode in
    open)
      heldout open "$dir" "$out/$m.zip$wrap" "$m$wrap" $old $ref $out/open "$shipped" "$out/$a.zip$wrap" "${others[@]}"
      python -m shelf_env.evaluation.compare "$dir/open" --pair "$m$wrap" $a$wrap --out "$dir/open/paired_a.md" ;;
    closed)
      heldout closed "$dir" "$out/$m.zip$wrap" "$m$wrap" $old $ref $out/closed_safe "$shipped" "$out/$a.zip$wrap" \
          "$ref=examples/pretrained/p_s.zip" h-d h-a
      python -m shelf_env.evaluation.compare "$dir/closed_safe" --pair "$m$wrap" $a$wrap \
          --out "$dir/closed_safe/paired_a.md" ;;
    falls)
      mkdir -p "$dir"
      python -m shelf_env.evaluation.falls "$out/$m.zip$wrap" --ns 8 --runs 30 --seed 0 --out "$dir/falls30.json" ;;
  esac
}
for x in c d e f g h; do
  for mode in open closed falls; do
    if [[ $step == "$mode$x" ]]; then
      held $mode "${!x}" "$out/$x"
    fi
  done
done
if [[ $step == series || $step == all ]]; then
  # what each shard series holds: the teacher's and the executed actions' primitives, the driver's greedy falls
  python -m research.series_actions data/teacher --out $out/series_actions.md
fi
