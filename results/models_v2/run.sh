#!/usr/bin/env bash
# The §V evaluation of the first distilled P+S, shipped on 2026-12-04 (docs/results.md): the P+S distilled from the
# teacher dataset (examples/pretrained/v2/p_s.zip since the next one replaced it, p_s.zip until then; its cells carry
# its distillation's name, p_s_dagger201_aug_mpa_r2_ce1_avg4; results/models_v3 is the next one's) beside the
# P+S it replaced (examples/pretrained/v1/p_s.zip, `p_s` in every result), S, H-d and H-a on issue 10's grid: N = 3..14,
# unseen YCB objects, 30 runs x 3 seeds, open loop (open/); and closed loop + safe picks on seed 0 (closed_safe/), as
# results/closed_loop/on_deeper_safe played v1 and the heuristics. The other policies' cells are copied from those
# folders (--reuse-cells: the same scenes and files, checked by digest), the distilled model's at N = 5, 8, 11 from
# results/distill_test. Resumable cell by cell; extra arguments go to shelf-evaluate (e.g. --workers 2).
#   bash results/models_v2/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
name=p_s_dagger201_aug_mpa_r2_ce1_avg4
d=$name=examples/pretrained/v2/p_s.zip  # the file shipped then, labelled with the name its cells carry
v1=examples/pretrained/v1/p_s.zip
s=examples/pretrained/s.zip
grid=(--ns 3-14 --runs 30 --object-sets ycb)
out=results/models_v2
shelf-evaluate --policies "$d" "${grid[@]}" --seeds 3 --out $out/open --reuse-cells results/distill_test "$@"
shelf-evaluate --policies "$v1" "$s" h-d h-a "${grid[@]}" --seeds 3 --out $out/open --reuse-cells results/models "$@"
shelf-evaluate --policies "$d" "$v1" "$s" h-d h-a "${grid[@]}" --seeds 3 --out $out/open --summarize-only
python -m shelf_env.evaluation.report $out/open --learned $name --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare $out/open --pair $name p_s --pair $name s --pair $name h-d --pair $name h-a \
  --out $out/open/paired.md
loop=(--closed-loop '{}' --safe-picks)
shelf-evaluate --policies "$d" "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe "$@"
shelf-evaluate --policies "$v1" h-d h-a "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe \
  --reuse-cells results/closed_loop/on_deeper_safe "$@"
shelf-evaluate --policies "$d" "$v1" h-d h-a "${grid[@]}" --seeds 1 "${loop[@]}" --out $out/closed_safe --summarize-only
python -m shelf_env.evaluation.report $out/closed_safe --learned $name --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare $out/closed_safe --pair $name p_s --pair $name h-d --pair $name h-a \
  --out $out/closed_safe/paired.md
