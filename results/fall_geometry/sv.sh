#!/usr/bin/env bash
# The seventeenth session's measurements of the filter + loop breaker (docs/experiments/fall-geometry.md,
# "Seventeenth session"), called by run.sh with its environment active; resumable cell by cell.
#   8. open loop on issue 10's whole grid (N = 3..14, 30 runs x seeds 0-2): the candidate's cells at N = 5, 8, 11
#      copied from heldout_lb/, the rest played; the shipped P+S, S, H-d, H-a from results/models_v3/open
#      -> sv_open/ (report.md, paired.md)
#   9. closed loop + safe picks (seed 0, N = 3..14); the other policies from results/models_v3/closed_safe
#      -> sv_closed_safe/ (report.md, paired.md)
#  10. the shipped P+S with the loop breaker alone on the held-out cells at N = 5, 8, 11 -> heldout_plb/,
#      heldout_plb_pairs.md
#  11. the filter + loop breaker's greedy fall rate per action at N = 8 (the first 30 held-out scenes, every decision
#      probed in a forked copy) -> falls30_lb.json
set -euo pipefail
cd "$(dirname "$0")/../.."
out=results/fall_geometry
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4
ship="$ref=examples/pretrained/p_s.zip"
lb="$out/filter/p_s_geo10.zip+geometry-filter+loop-breaker"
l=p_s_geo10+geometry-filter+loop-breaker
w=(--workers "${WORKERS:-1}")
grid=(--ns 3-14 --runs 30 --object-sets ycb)
python -m research.evaluate --policies "$lb" "${grid[@]}" --seeds 3 "${w[@]}" --out "$out/sv_open" \
    --reuse-cells "$out/heldout_lb"
python -m research.evaluate --policies "$ship" examples/pretrained/s.zip h-d h-a "${grid[@]}" --seeds 3 "${w[@]}" \
    --out "$out/sv_open" --reuse-cells results/models_v3/open
python -m research.evaluate --policies "$lb" "$ship" examples/pretrained/s.zip h-d h-a "${grid[@]}" --seeds 3 \
    --out "$out/sv_open" --summarize-only
python -m shelf_env.evaluation.report "$out/sv_open" --learned $l --pick-only s --heuristics h-d h-a
python -m shelf_env.evaluation.compare "$out/sv_open" --pair $l $ref --pair $l h-d --pair $l h-a \
    --out "$out/sv_open/paired.md"
loop=(--closed-loop '{}' --safe-picks --seeds 1 --out "$out/sv_closed_safe")
python -m research.evaluate --policies "$lb" "${grid[@]}" "${loop[@]}" "${w[@]}"
python -m research.evaluate --policies "$ship" h-d h-a "${grid[@]}" "${loop[@]}" "${w[@]}" \
    --reuse-cells results/models_v3/closed_safe
python -m research.evaluate --policies "$lb" "$ship" h-d h-a "${grid[@]}" "${loop[@]}" --summarize-only
python -m shelf_env.evaluation.report "$out/sv_closed_safe" --learned $l --heuristics h-d h-a
python -m shelf_env.evaluation.compare "$out/sv_closed_safe" --pair $l $ref --pair $l h-d --pair $l h-a \
    --out "$out/sv_closed_safe/paired.md"
held=(--ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb --out "$out/heldout_plb")
python -m research.evaluate --policies "$ship+loop-breaker" "${held[@]}" "${w[@]}"
python -m research.evaluate --policies "$lb" "$ship" "${held[@]}" "${w[@]}" --reuse-cells "$out/heldout_lb"
python -m research.evaluate --policies "$ship+loop-breaker" "$lb" "$ship" "${held[@]}" --summarize-only
python -m shelf_env.evaluation.compare "$out/heldout_plb" --pair $l "$ref+loop-breaker" \
    --pair "$ref+loop-breaker" $ref --out "$out/heldout_plb_pairs.md"
[ -f "$out/falls30_lb.json" ] || python -c "import research.fall_geometry, sys; from shelf_env.evaluation.falls import \
main; sys.exit(main(sys.argv[1:]))" "$lb" --ns 8 --runs 30 --seed 0 --out "$out/falls30_lb.json"
