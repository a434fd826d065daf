#!/usr/bin/env bash
# Fine-tune a distilled P+S with PixelDoubleDQN (the paper's loss) and the teacher dataset as demonstrations
# (docs/experiments/distill-scaling.md), N drawn from 3..11 each episode, no greedy checks (one stage).
#   bash results/distill_finetune/train.sh HOURS INIT OUT     # resumable: run it again to continue
# The two runs of the page:
#   bash results/distill_finetune/train.sh 0.75 runs/distill_scaling/p_s_dall_aug_m.zip runs/distill_finetune
#   bash results/distill_finetune/train.sh 0.5 runs/distill_scaling/p_s_dall_aug_mpa.zip runs/distill_finetune_mpa
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
INIT=${2:-runs/distill_scaling/p_s_dall_aug_mpa.zip}
OUT=${3:-runs/distill_finetune_mpa}
[ -f "$INIT" ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-train --out "$OUT" --preset p_s --init-from "$INIT" \
  --set demo_policy=null --set demo_data=data/teacher \
  --start-objects 11 --max-objects 11 --min-num-objects 3 --eval-every 1000000 \
  --exploration-initial-eps 0.1 --exploration-final-eps 0.01 --exploration-timesteps 1000 \
  --learning-starts 100 --learning-rate 1e-4 --threads 1 --checkpoint-minutes 10 --hours "${1:-0.75}"
