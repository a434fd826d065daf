#!/usr/bin/env bash
# Issue 10's evaluation (§V, Fig. 10 and Fig. 12): the P+S and S models trained with PixelDoubleDQN
# (examples/pretrained/v1/p_s.zip, shipped as p_s.zip until 2026-12-04, and s.zip) beside H-d and H-a
# on N = 3..14 unseen YCB objects, 30 runs x 3 seeds, the same scenes for every policy; P+S also on
# the training objects (Fig. 12). The distilled P+S shipped since then: bash results/models_v2/run.sh.
# Resumable cell by cell: run it again to continue. Extra arguments
# go to shelf-evaluate (e.g. --workers 16, or --backend ray --ray-address HOST:PORT).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
# Models not shipped yet are left out (a note says so); their cells are added when the script runs
# again after they ship, the other cells being reused.
shipped=()
for zip in examples/pretrained/v1/p_s.zip examples/pretrained/s.zip; do
  if [ -f "$zip" ]; then shipped+=("$zip"); else echo "note: $zip not shipped yet (train_model.sh, ship_models.sh); left out" >&2; fi
done
[ -f examples/pretrained/v1/p_s.zip ] || { echo "missing examples/pretrained/v1/p_s.zip: train and ship it first" >&2; exit 2; }
shelf-evaluate --policies "${shipped[@]}" h-d h-a --ns 3-14 \
    --runs 30 --seeds 3 --object-sets ycb --out results/models "$@"
# Fig. 12: P+S on the training objects beside YCB; its YCB cells are the ones above, copied
# (--reuse-cells) rather than run twice.
shelf-evaluate --policies examples/pretrained/v1/p_s.zip --ns 3-14 --runs 30 --seeds 3 \
    --object-sets train ycb --out results/models_train_vs_ycb --reuse-cells results/models "$@"
# The verdict against issue 10's targets (results/models/report.md: table, margins, failures).
python -m shelf_env.evaluation.report results/models
# Where the falls come from: up to 10 fallen episodes per (policy, N) replayed with the motion's
# phases watched (results/models/falls.md, traces.jsonl).
python -m shelf_env.evaluation.traces results/models --policies "${shipped[@]}" h-d h-a --ns 3 5 8 11 14 --limit 10
