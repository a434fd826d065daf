#!/usr/bin/env bash
# Copy the shipped models to examples/pretrained/ and write examples/pretrained/README.md, their cards
# (python -m shelf_env.training.ship): every finished run (results/training/s -> s.zip; results/training/p_s ->
# v1/p_s.zip, the P+S trained with PixelDoubleDQN, shipped as p_s.zip until 2026-12-04) and, with
# --distilled ZIP, a distilled P+S as p_s.zip with its report (a distilled p_s.zip already on the shelf keeps
# its card; one that ZIP replaces moves to v<k>/, k >= 2, with its report and card), and with --geometry-risk FILE
# --geometry-label LABEL the camera-only pick filter the shelf's p_s.zip is played under (the card then names
# p_s.zip with LABEL's wrappers as the policy to use: p_s.zip+geometry-filter+pick-guard+loop-breaker since the
# eighteenth session). Each card's evaluation table comes from the first of results/models_v5/open (the guarded
# P+S's §V evaluation), results/models_v4/open (the filtered P+S's), results/models_v3/open, results/models_v2/open
# (the distilled P+S's) and results/models (issue 10's) that evaluated it, where they are complete.
# Order: train_model.sh p_s|s or distill -> ship_models.sh -> evaluate_models.sh / results/models_v2/run.sh ->
# ship_models.sh (the cards' tables). The distilled P+S shipped on 2026-12-04 (now v2/p_s.zip), then the one that
# replaced it the same day (results/models_v3):
#   bash scripts/ship_models.sh --distilled runs/distill_scaling/p_s_dagger201_aug_mpa_r2_ce1_avg4.zip
#   bash scripts/ship_models.sh --distilled data/candidates/p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4.zip
# and its geometry pick filter (docs/experiments/fall-geometry.md, the seventeenth session):
#   bash scripts/ship_models.sh --geometry-risk results/fall_geometry/filter/p_s_geo10.geometry_risk.pt \
#       --geometry-label p_s_geo10+geometry-filter+loop-breaker
# and the same filter with the pick guard (docs/experiments/pick-guard.md, the eighteenth session):
#   bash scripts/ship_models.sh --geometry-risk results/fall_geometry/filter/p_s_geo10.geometry_risk.pt \
#       --geometry-label p_s_geo10+geometry-filter+pick-guard+loop-breaker
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
folders=()
for f in results/models_v5/open results/models_v4/open results/models_v3/open results/models_v2/open results/models; do
  if [ -f $f/results.json ] && python -c "import json,sys; sys.exit(0 if json.load(open('$f/results.json'))['config'].get('complete') else 1)"; then
    folders+=("$f")
  fi
done
args=()
[ ${#folders[@]} -gt 0 ] && args+=(--results "${folders[@]}")
python -m shelf_env.training.ship "${args[@]}" "$@"
