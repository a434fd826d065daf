#!/usr/bin/env bash
# Fine-tune the distilled P+S with PixelDoubleDQN (the paper's loss) and the teacher dataset as demonstrations
# (docs/experiments/distill-scaling.md): from results/distill_scaling's p_s_dall_aug_m (all states, augmented,
# teacher margin over every allowed action), N drawn from 3..11 each episode, no greedy checks (one stage).
#   bash results/distill_finetune/train.sh [HOURS]     # resumable: run it again to continue
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
INIT=runs/distill_scaling/p_s_dall_aug_m.zip
[ -f "$INIT" ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-train --out runs/distill_finetune --preset p_s --init-from "$INIT" \
  --set demo_policy=null --set demo_data=data/teacher \
  --start-objects 11 --max-objects 11 --min-num-objects 3 --eval-every 1000000 \
  --exploration-initial-eps 0.1 --exploration-final-eps 0.01 --exploration-timesteps 1000 \
  --learning-starts 100 --learning-rate 1e-4 --threads 1 --checkpoint-minutes 10 --hours "${1:-0.75}"
