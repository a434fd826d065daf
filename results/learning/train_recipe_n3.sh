#!/usr/bin/env bash
# The learning recipe's N = 3 check (issue 9, docs/experiments/learning-recipe.md): P+S with the "recipe" preset of
# shelf_env/training/config.py, started and kept at N = 3, seed 0, two torch threads, 30 minutes of wall
# clock (demonstrations included; the issue allows up to 90). This run is also the ablation's
# "recipe" row.
#   1. train runs/ablation/recipe_s0 (resumes until its budget is spent; nothing to do after);
#   2. the ablation row: held-out evaluation -> results/learning/rows/recipe_s0.json (skipped when on disk);
#   3. copy the checkpoint to results/learning/recipe_n3.zip, with its progress, episodes and curve;
#   4. the issue's N = 3 criteria on held-out scenes, beside H-d -> results/learning/recipe_n3_check.json.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
python examples/train.py --out runs/ablation/recipe_s0 --preset recipe --start-objects 3 --max-objects 3 \
    --seed 0 --hours 0.5 --threads 2 --checkpoint-minutes 5
python research/ablation.py --rows recipe --minutes 30 --threads 2
mkdir -p results/learning
cp runs/ablation/recipe_s0/model.zip results/learning/recipe_n3.zip
cp runs/ablation/recipe_s0/progress.json results/learning/recipe_n3_progress.json
cp runs/ablation/recipe_s0/episodes.csv results/learning/recipe_n3_episodes.csv
python examples/plot_training.py runs/ablation/recipe_s0 --png docs/recipe_n3_curve.png
python research/check_recipe.py results/learning/recipe_n3.zip --scenes 50 --out results/learning/recipe_n3_check.json
