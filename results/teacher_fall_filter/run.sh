#!/usr/bin/env bash
# A fall filter learned from the teacher dataset (docs/experiments/teacher-fall-filter.md), from the committed
# shards to the validation table:
#   1. train: research.fall_risk's FCN, started from the shipped P+S's pick FCN, on the pick labels of the 374
#      shards the fourteenth session started with (split by scene as the distillation splits it: the last 20 %
#      of each series' scenes held out; they choose the epoch and the balanced-accuracy threshold)
#      -> model/p_s_ffbal.fall_risk.pt; the same weights with the highest threshold that flags 90 % of the
#      held-out falls -> model/p_s_ffr90.fall_risk.pt. Each beside a copy of examples/pretrained/p_s.zip
#      (p_s_ffbal.zip, p_s_ffr90.zip; not committed), so `<zip>+fall-filter` plays the shipped P+S under it.
#   2. check: each filter's effect on the shipped model's choice among the labelled picks of the held-out
#      scenes (invalid share and change in sorted objects, at its threshold, over a sweep of thresholds and
#      under a perfect filter; the AUC overall and per N) -> greedy_check_bal.json, greedy_check_r90.json
#   3. validation scenes (evaluation seeds 2000-2002, 30 YCB scenes each at N = 5, 8, 11, open loop): both
#      filtered policies, beside the shipped model's cells copied from results/distill_scaling/val90 (the
#      same file: p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4) -> val90/, val90_pairs.md
# Each step skips what is on disk; WORKERS (default 1) evaluation processes.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
export OMP_NUM_THREADS=1
out=results/teacher_fall_filter
dir=$out/model
shipped=examples/pretrained/p_s.zip
shards=s00:55,s01:50,s02:205,s03:54,s04:10
mkdir -p "$dir"
cp -p "$shipped" "$dir/p_s_ffbal.zip"
cp -p "$shipped" "$dir/p_s_ffr90.zip"
if [ ! -f "$dir/p_s_ffbal.fall_risk.pt" ]; then
    python -m research.fall_risk train --data data/teacher --max-shards "$shards" --val-fraction 0.2 \
        --init "$shipped" --epochs 8 --out "$dir/p_s_ffbal.fall_risk.pt" | tee "$out/train.log"
fi
if [ ! -f "$dir/p_s_ffr90.fall_risk.pt" ]; then
    python -m research.fall_risk threshold --data data/teacher --model "$dir/p_s_ffbal.fall_risk.pt" --recall 0.9 \
        --out "$dir/p_s_ffr90.fall_risk.pt"
fi
for f in bal r90; do
    [ -f "$out/greedy_check_$f.json" ] || python -m research.fall_risk check --data data/teacher \
        --model "$dir/p_s_ff$f.fall_risk.pt" --checkpoint "$shipped" --out "$out/greedy_check_$f.json"
done
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4
python -m research.evaluate --policies "$dir/p_s_ffbal.zip+fall-filter" "$dir/p_s_ffr90.zip+fall-filter" \
    "$ref=$shipped" --ns 5,8,11 --runs 30 --seeds 3 --first-seed 2000 --object-sets ycb \
    --workers "${WORKERS:-1}" --out "$out/val90" --reuse-cells results/distill_scaling/val90
python -m shelf_env.evaluation.compare "$out/val90" --pair p_s_ffbal+fall-filter "$ref" \
    --pair p_s_ffr90+fall-filter "$ref" --pair p_s_ffr90+fall-filter p_s_ffbal+fall-filter --out "$out/val90_pairs.md"
# 4. the fall model's scaling curve: the same recipe on the first 1,675 / 3,349 / 6,698 training states (the held-out
#    scenes unchanged), each checked at its balanced threshold -> curve/ff_<states>.fall_risk.pt, curve/check_<states>.json
#    (the full model is step 1's)
mkdir -p "$out/curve"
for k in 1675 3349 6698; do
    [ -f "$out/curve/ff_$k.fall_risk.pt" ] || python -m research.fall_risk train --data data/teacher \
        --max-shards "$shards" --max-states "$k" --val-fraction 0.2 --init "$shipped" --epochs 8 \
        --out "$out/curve/ff_$k.fall_risk.pt" | tee "$out/curve/train_$k.log"
    [ -f "$out/curve/check_$k.json" ] || python -m research.fall_risk check --data data/teacher \
        --model "$out/curve/ff_$k.fall_risk.pt" --checkpoint "$shipped" --out "$out/curve/check_$k.json"
done
# 5. the same recipe with two coordinate channels (--coords: depth, distance from the centre line), all training states
#    -> curve/ff_coords.fall_risk.pt, curve/check_coords.json
[ -f "$out/curve/ff_coords.fall_risk.pt" ] || python -m research.fall_risk train --data data/teacher \
    --max-shards "$shards" --coords --val-fraction 0.2 --init "$shipped" --epochs 8 \
    --out "$out/curve/ff_coords.fall_risk.pt" | tee "$out/curve/train_coords.log"
[ -f "$out/curve/check_coords.json" ] || python -m research.fall_risk check --data data/teacher \
    --model "$out/curve/ff_coords.fall_risk.pt" --checkpoint "$shipped" --out "$out/curve/check_coords.json"
# 6. (the fifteenth session) the same recipe from scratch (--init none): all training states, then the first 1,675 and
#    6,698 (the 3,349 point: results/fall_visibility/compare_scratch.json's camera row), and the full model's offline
#    check of docs/experiments/object-fall-penalty.md -> scratch/
mkdir -p "$out/scratch"
[ -f "$out/scratch/ff_scratch.fall_risk.pt" ] || python -m research.fall_risk train --data data/teacher \
    --max-shards "$shards" --val-fraction 0.2 --init none --epochs 8 --out "$out/scratch/ff_scratch.fall_risk.pt" \
    | tee "$out/scratch/train_scratch.log"
[ -f "$out/scratch/penalty_scratch.json" ] || python -m research.fall_risk penalty --data data/teacher \
    --model "$out/scratch/ff_scratch.fall_risk.pt" --checkpoint "$shipped" --out "$out/scratch/penalty_scratch.json" \
    > /dev/null
for k in 1675 6698; do
    [ -f "$out/scratch/ff_scratch_$k.fall_risk.pt" ] || python -m research.fall_risk train --data data/teacher \
        --max-shards "$shards" --max-states "$k" --val-fraction 0.2 --init none --epochs 8 \
        --out "$out/scratch/ff_scratch_$k.fall_risk.pt" | tee "$out/scratch/train_scratch_$k.log"
done
# 7. (the fifteenth session, after fall-visibility's neighbour check) the labels spread over their objects, from scratch
#    -> scratch/ff_spread.fall_risk.pt (its offline check only if its held-out AUC reaches 0.886: the page's rule)
[ -f "$out/scratch/ff_spread.fall_risk.pt" ] || python -m research.fall_risk train --data data/teacher \
    --max-shards "$shards" --val-fraction 0.2 --init none --spread --epochs 8 \
    --out "$out/scratch/ff_spread.fall_risk.pt" | tee "$out/scratch/train_spread.log"
