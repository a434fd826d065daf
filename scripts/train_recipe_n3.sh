#!/usr/bin/env bash
# The learning recipe's N = 3 check (issue 9, docs/learning.md): P+S with the "recipe" preset of
# shelf_env/training.py, started and kept at N = 3, 90 minutes of wall clock (demonstrations
# included), one torch thread. Re-running resumes from runs/recipe_n3 until the budget is spent;
# then the final model is copied to results/learning/recipe_n3.zip and evaluated on held-out scenes.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
python examples/train.py --out runs/recipe_n3 --preset recipe --start-objects 3 --max-objects 3 \
    --hours 1.5 --threads 1 --seed 0 "$@"
mkdir -p results/learning
cp runs/recipe_n3/model.zip results/learning/recipe_n3.zip
cp runs/recipe_n3/progress.json results/learning/recipe_n3_progress.json
python examples/check_recipe.py results/learning/recipe_n3.zip --scenes 50 --out results/learning/recipe_n3_check.json
