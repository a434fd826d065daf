#!/usr/bin/env bash
# Issue 10's evaluation (§V, Fig. 10 and Fig. 12): the shipped P+S and S models beside H-d and H-a
# on N = 3..14 unseen YCB objects, 30 runs x 3 seeds, the same scenes for every policy; P+S also on
# the training objects (Fig. 12). Resumable cell by cell: run it again to continue. Extra arguments
# go to shelf-evaluate (e.g. --workers 16, or --backend ray --ray-address HOST:PORT).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
for zip in examples/pretrained/p_s.zip examples/pretrained/s.zip; do
  [ -f "$zip" ] || { echo "missing $zip: train it first (bash scripts/train_model.sh p_s|s)" >&2; exit 2; }
done
shelf-evaluate --policies examples/pretrained/p_s.zip examples/pretrained/s.zip h-d h-a --ns 3-14 \
    --runs 30 --seeds 3 --object-sets ycb --out results/models "$@"
shelf-evaluate --policies examples/pretrained/p_s.zip --ns 3-14 --runs 30 --seeds 3 \
    --object-sets train ycb --out results/models_train_vs_ycb "$@"
