#!/usr/bin/env bash
# The §V evaluation of the P+S shipped since 2026-12-04 (the twelfth session; docs/results.md): the candidate chosen
# on validation scenes (docs/experiments/distill-scaling.md, "Eleventh session"), evaluated as
# data/candidates/p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4.zip and shipped by the tenth session's rule as
# examples/pretrained/p_s.zip (the same bytes; its cells carry that name), beside the distilled P+S it replaced
# (examples/pretrained/v2/p_s.zip, labelled p_s_dagger201_aug_mpa_r2_ce1_avg4 as in results/models_v2), v1 P+S
# (`p_s`), S, H-d and H-a on issue 10's grid: N = 3..14, unseen YCB objects, 30 runs x 3 seeds, open loop (open/); and
# closed loop + safe picks on seed 0 (closed_safe/). Only the new model is played here; every other policy's cells
# are copied from results/models_v2 (--reuse-cells: the same scenes and files, checked by digest). The shipping rule
# read open/paired.md and closed_safe/paired.md. Resumable cell by cell; extra arguments go to shelf-evaluate (e.g.
# --workers 2).
#   bash results/models_v3/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
cand=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4
c=$cand=examples/pretrained/p_s.zip  # the shipped file, labelled with the name its cells carry
ship=p_s_dagger201_aug_mpa_r2_ce1_avg4
d=$ship=examples/pretrained/v2/p_s.zip  # the model it replaced, likewise
v1=examples/pretrained/v1/p_s.zip
s=examples/pretrained/s.zip
grid=(--ns 3-14 --runs 30 --object-sets ycb)
out=results/models_v3
shelf-evaluate --policies "$c" "${grid[@]}" --seeds 3 --out $out/open "$@"
shelf-evaluate --policies "$d" "$v1" "$s" h-d h-a "${grid[@]}" --seeds 3 --out $out/open \
  --reuse-cells results/models_v2/open "$@"
shelf-evaluate --policies "$c" "$d" "$v1" "$s" h-d h-a "${grid[@]}" --seeds 3 --out $out/open --summarize-only
python -m shelf_env.evaluation.report $out/open --learned $cand --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare $out/open --pair $cand $ship --pair $cand p_s --pair $cand s \
  --pair $cand h-d --pair $cand h-a --out $out/open/paired.md
loop=(--closed-loop '{}' --safe-picks)
shelf-evaluate --policies "$c" "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe "$@"
shelf-evaluate --policies "$d" "$v1" h-d h-a "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe \
  --reuse-cells results/models_v2/closed_safe "$@"
shelf-evaluate --policies "$c" "$d" "$v1" h-d h-a "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe \
  --summarize-only
python -m shelf_env.evaluation.report $out/closed_safe --learned $cand --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare $out/closed_safe --pair $cand $ship --pair $cand p_s --pair $cand h-d \
  --pair $cand h-a --out $out/closed_safe/paired.md
