#!/usr/bin/env bash
# Fine-tune the shipped P+S model on a mix of sizes under issue 13's recommended setting (closed
# loop with the watch's defaults, safe picks): a new run from examples/pretrained/v1/p_s.zip's weights
# (shelf-train --init-from) in which every training episode draws its N uniformly from 3..13
# (TrainConfig.min_num_objects = 3 under one curriculum stage N = 13), so that training past N = 8
# does not forget the low N as the staged fine-tune (results/loop_breaker/finetune_closed_loop.sh) did. 400 H-a
# demonstration steps drawn the same way under the same setting, a quarter of each batch from them,
# exploration from 0.1, the actor process, no greedy checks within the budget (a single stage has
# no gate to pass; eval_every beyond the run), the "p_s" preset otherwise. Resumable like
# train_model.sh (runs/p_s_mixed, mirrored to results/training/p_s_mixed). Then it plays the
# fine-tuned model with the loop breaker on issue 10's YCB grid (N = 3..14, 30 runs, seeds 0 and 1)
# under the same setting, beside the policies of results/loop_breaker/closed_safe (whose cells it
# reuses), and writes report.md. Extra arguments go to shelf-train (e.g. --hours 0.5; the budget is
# the run's total over all resumes). SUFFIX names a later snapshot of the same run, so that the
# earlier one's zip and evaluation stay as committed: SUFFIX=_long bash results/loop_breaker/finetune_mixed.sh
# --hours 2.25 resumes the run to 2.25 hours in all, copies the model to
# results/training/p_s_mixed_long.zip and evaluates it into results/loop_breaker/closed_safe_mixed_long.
# RUN names another run of the same recipe (runs/$RUN, results/training/$RUN[.zip], evaluated into
# results/loop_breaker/closed_safe_${RUN#p_s_}) and INIT the zip it starts from, e.g. the progress
# reward from the one-hour snapshot: RUN=p_s_progress INIT=results/training/p_s_mixed.zip
# bash results/loop_breaker/finetune_mixed.sh --set progress_reward=1 --hours 1.0, or a fall penalty of -30:
# RUN=p_s_fall30 INIT=results/training/p_s_mixed.zip bash results/loop_breaker/finetune_mixed.sh --set invalid_reward=-30 --hours 0.6.
set -euo pipefail
suffix=${SUFFIX:-}
run=${RUN-p_s_mixed}
init=${INIT:-examples/pretrained/v1/p_s.zip}
for name in "$suffix" "$run"; do
    case $name in *[!A-Za-z0-9_-]*) echo "SUFFIX and RUN may hold only letters, digits, _ and - (got: $name)" >&2; exit 2;; esac
done
[ -n "$run" ] || { echo "RUN must not be empty" >&2; exit 2; }
cd "$(dirname "$0")/../.."
[ -f "$init" ] || { echo "INIT: no such checkpoint: $init" >&2; exit 2; }
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-train --out "runs/$run" --mirror "results/training/$run" --preset p_s --seed 0 --threads 2 \
    --actor --init-from "$init" --set safe_picks=true --set closed_loop=true \
    --set min_num_objects=3 --start-objects 13 --max-objects 13 --max-stage-timesteps 50000 \
    --set exploration_initial_eps=0.1 --set 'demo_objects=[13]' --set demo_fraction=0.25 \
    --set eval_every=1000000 --checkpoint-minutes 10 --hours 0.95 "$@"
python examples/plot_training.py "results/training/$run" --png "results/training/$run/curve.png"
cp "results/training/$run/model.zip" "results/training/$run$suffix.zip.tmp"
mv "results/training/$run$suffix.zip.tmp" "results/training/$run$suffix.zip"
bash results/loop_breaker/evaluate_closed_safe.sh "results/training/$run$suffix.zip" "results/loop_breaker/closed_safe_${run#p_s_}$suffix"
