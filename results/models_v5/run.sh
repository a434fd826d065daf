#!/usr/bin/env bash
# The §V evaluation of the P+S shipped since 2026-12-05 (the eighteenth session; docs/results.md): the shelf's
# p_s.zip played under its geometry pick filter, the pick guard and the loop breaker,
# examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker, shipped by the rule written before its numbers
# in docs/experiments/pick-guard.md. Its cells carry the label they were played under,
# p_s_geo10+geometry-filter+pick-guard+loop-breaker (results/fall_geometry/filter/p_s_geo10.zip and .geometry_risk.pt:
# the same bytes as the shelf's p_s.zip and p_s.geometry_risk.pt), and are copied from results/pick_guard (open,
# closed_safe; --reuse-cells checks the files by digest); every other policy's from results/models_v4, on issue 10's
# grid: N = 3..14, unseen YCB objects, 30 runs x 3 seeds, open loop (open/); closed loop + safe picks on seed 0
# (closed_safe/). Resumable cell by cell (a missing cell is played); extra arguments go to shelf-evaluate.
#   bash results/models_v5/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
new=p_s_geo10+geometry-filter+pick-guard+loop-breaker
g=p_s_geo10=examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker  # the shipped policy, its cells' label
old=p_s_geo10+geometry-filter+loop-breaker
f=p_s_geo10=examples/pretrained/p_s.zip+geometry-filter+loop-breaker  # the P+S shipped before (results/models_v4)
ship=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4
d=$ship=examples/pretrained/p_s.zip  # the same Q-maps alone (results/models_v3)
v2=p_s_dagger201_aug_mpa_r2_ce1_avg4=examples/pretrained/v2/p_s.zip
v1=examples/pretrained/v1/p_s.zip
s=examples/pretrained/s.zip
grid=(--ns 3-14 --runs 30 --object-sets ycb)
out=results/models_v5
shelf-evaluate --policies "$g" "${grid[@]}" --seeds 3 --out $out/open --reuse-cells results/pick_guard/open "$@"
shelf-evaluate --policies "$f" "$d" "$v2" "$v1" "$s" h-d h-a "${grid[@]}" --seeds 3 --out $out/open \
  --reuse-cells results/models_v4/open "$@"
shelf-evaluate --policies "$g" "$f" "$d" "$v2" "$v1" "$s" h-d h-a "${grid[@]}" --seeds 3 --out $out/open \
  --summarize-only
python -m shelf_env.evaluation.report $out/open --learned $new --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare $out/open --pair $new $old --pair $new $ship --pair $new s --pair $new h-d \
  --pair $new h-a --out $out/open/paired.md
loop=(--closed-loop '{}' --safe-picks)
shelf-evaluate --policies "$g" "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe \
  --reuse-cells results/pick_guard/closed_safe "$@"
shelf-evaluate --policies "$f" "$d" "$v2" "$v1" h-d h-a "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe \
  --reuse-cells results/models_v4/closed_safe "$@"
shelf-evaluate --policies "$g" "$f" "$d" "$v2" "$v1" h-d h-a "${grid[@]}" --seeds 1 "${loop[@]}" \
  --out $out/closed_safe --summarize-only
python -m shelf_env.evaluation.report $out/closed_safe --learned $new --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare $out/closed_safe --pair $new $old --pair $new $ship --pair $new h-d \
  --pair $new h-a --out $out/closed_safe/paired.md
