#!/usr/bin/env bash
# The distilled P+S on held-out scenes (docs/experiments/distill-scaling.md): the §V comparison's YCB scenes
# (issue 10's grid: seed 0, 30 runs) at N = 5, 8, 11, open loop, beside the shipped P+S, S, H-d and H-a
# (their cells reused from results/models) and the shipped P+S with the same test-time loop breaker.
# No choice of this work read these scenes (the recipes were chosen on evaluation seed 2000).
#   bash results/distill_test/run.sh [--workers 2]     # resumable cell by cell
set -euo pipefail
cd "$(dirname "$0")/../.."
[ -f runs/distill_scaling/p_s_dall_aug_mpa.zip ] || bash results/distill_scaling/run.sh
d=runs/distill_scaling/p_s_dall_aug_mpa.zip
ps=examples/pretrained/v1/p_s.zip
.venv/bin/shelf-evaluate --policies "$d" "$d+loop-breaker" "$ps+loop-breaker" "$ps" examples/pretrained/s.zip h-d h-a \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/distill_test --reuse-cells results/models "$@"
# the greedy action's invalid actions per action on the first 10 of those scenes at N = 8, each action tried
# first in a copy of the simulator (shelf_env.evaluation.falls)
.venv/bin/python -m shelf_env.evaluation.falls "$ps" "$d" "$d+loop-breaker" h-d --ns 8 --runs 10 --seed 0 \
  --out results/distill_test/falls.json

# Recipe D's scaling curve on these held-out scenes (the recipe was fixed before; the points differ only in
# the states distilled: 220, 440, 822 from the first 35 shards, 1,325 from the first 52), the greedy action's
# invalid actions per action and SR on the first 10 scenes at N = 5, 8, 11, and the 1,325-state model's SR on
# all 30 scenes per N
M=runs/distill_scaling
[ -f $M/p_s_d52sh_aug_mpa.zip ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-evaluate --policies $M/p_s_d52sh_aug_mpa.zip \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/distill_test --reuse-cells results/models "$@"
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_d52sh_aug_mpa.zip "$ps" h-d "$d" --ns 8 5 11 --runs 10 \
  --seed 0 --out results/distill_test/falls.json
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_d440_aug_mpa.zip $M/p_s_d220_aug_mpa.zip --ns 8 5 11 \
  --runs 10 --seed 0 --out results/distill_test/falls.json
# the heuristics with the same test-time loop breaker, so that the loop-breaker rows compare like with like
.venv/bin/shelf-evaluate --policies h-d+loop-breaker h-a+loop-breaker \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/distill_test "$@"
# the DAgger-series model (recipe D from the first 55 shards of series 0 and 7 of series 1), all 30 scenes per N
[ -f $M/p_s_dagger7_aug_mpa.zip ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-evaluate --policies $M/p_s_dagger7_aug_mpa.zip \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/distill_test "$@"
# ... and with the teacher term as a cross-entropy (chosen on the validation scenes: 30 % at N = 8 there)
[ -f $M/p_s_dagger7_aug_mpa_r2_ce1.zip ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-evaluate --policies $M/p_s_dagger7_aug_mpa_r2_ce1.zip \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/distill_test "$@"
# ... the same recipe at the third session's dataset (55 + 19 shards): the cross-entropy term's scaling point
[ -f $M/p_s_dagger19_aug_mpa_r2_ce1.zip ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-evaluate --policies $M/p_s_dagger19_aug_mpa_r2_ce1.zip \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out results/distill_test "$@"
# the cross-entropy models' and the DAgger model's greedy invalid actions per action on the first 10 scenes at N = 8
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_dagger19_aug_mpa_r2_ce1.zip $M/p_s_dagger7_aug_mpa_r2_ce1.zip \
  $M/p_s_dagger7_aug_mpa.zip --ns 8 --runs 10 --seed 0 --out results/distill_test/falls.json
# the fifth session: the cross-entropy recipe at 55 + 48 shards (3,626 training states), its falls at N = 8, 5, 11,
# then the cross-entropy curve's three models, the shipped P+S, S and the heuristics on all three seeds of issue 10's
# grid at N = 5, 8, 11 (90 scenes per N; the seed 1 and 2 cells of p_s, s, h-d and h-a copied from results/models)
[ -f $M/p_s_dagger48_aug_mpa_r2_ce1.zip ] || bash results/distill_scaling/run.sh
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_dagger48_aug_mpa_r2_ce1.zip --ns 8 5 11 --runs 10 --seed 0 \
  --out results/distill_test/falls.json
.venv/bin/shelf-evaluate --policies "$ps" examples/pretrained/s.zip h-d h-a --ns 5,8,11 --runs 30 --seeds 3 \
  --object-sets ycb --out results/distill_test --reuse-cells results/models "$@"
# the sixth session: the same recipe at 55 + 50 + 25 shards (the fourth point of the curve), its falls likewise
[ -f $M/p_s_dagger75_aug_mpa_r2_ce1.zip ] || bash results/distill_scaling/run.sh
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_dagger75_aug_mpa_r2_ce1.zip --ns 8 5 11 --runs 10 --seed 0 \
  --out results/distill_test/falls.json
for m in p_s_dagger75_aug_mpa_r2_ce1 p_s_dagger48_aug_mpa_r2_ce1 p_s_dagger19_aug_mpa_r2_ce1 p_s_dagger7_aug_mpa_r2_ce1; do
  .venv/bin/shelf-evaluate --policies $M/$m.zip --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb \
    --out results/distill_test "$@"
done
# ... the 4,797-state model fine-tuned for 30 min with PixelDoubleDQN (the paper's loss, the dataset of the time as
# demonstrations: 154 shards), on the same scenes, and its falls at N = 8
FT=$M/p_s_dagger75_aug_mpa_r2_ce1_ft30.zip
if [ ! -f $FT ]; then
  bash results/distill_finetune/train.sh 0.5 $M/p_s_dagger75_aug_mpa_r2_ce1.zip runs/distill_finetune_ce75
  cp runs/distill_finetune_ce75/model.zip $FT
fi
.venv/bin/shelf-evaluate --policies $FT --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb --out results/distill_test "$@"
.venv/bin/python -m shelf_env.evaluation.falls $FT --ns 8 --runs 10 --seed 0 --out results/distill_test/falls.json
# the seventh session: the same recipe at 55 + 50 + 65 shards (the fifth point), and it fine-tuned as the fourth was
# (train.sh with a 45-min budget, which ends at the p_s preset's 5,000-step stage cap: 24.3 min on an idle core),
# each also under the loop breaker
[ -f $M/p_s_dagger115_aug_mpa_r2_ce1.zip ] || bash results/distill_scaling/run.sh
FT2=$M/p_s_dagger115_aug_mpa_r2_ce1_ft5k.zip
if [ ! -f $FT2 ]; then
  bash results/distill_finetune/train.sh 0.75 $M/p_s_dagger115_aug_mpa_r2_ce1.zip runs/distill_finetune_ce115
  cp runs/distill_finetune_ce115/model.zip $FT2
fi
for m in $M/p_s_dagger115_aug_mpa_r2_ce1.zip $FT2; do
  .venv/bin/shelf-evaluate --policies $m $m+loop-breaker --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb \
    --out results/distill_test "$@"
  .venv/bin/python -m shelf_env.evaluation.falls $m --ns 8 --runs 10 --seed 0 --out results/distill_test/falls.json
done
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_dagger115_aug_mpa_r2_ce1.zip+loop-breaker --ns 8 --runs 10 --seed 0 \
  --out results/distill_test/falls.json
# ... and the same loop breaker on the heuristics and the shipped P+S over the same three seeds (like with like)
.venv/bin/shelf-evaluate --policies h-d+loop-breaker h-a+loop-breaker "$ps+loop-breaker" --ns 5,8,11 --runs 30 --seeds 3 \
  --object-sets ycb --out results/distill_test "$@"
# the eighth session: the same recipe at all 205 shards the dataset held at its start (55 + 50 + 100: the sixth point),
# the fifth and sixth points distilled again at seed 1, and the sixth point's data with its weights averaged over the
# last 4 epochs (results/distill_scaling/run.sh), each on all three seeds at N = 5, 8, 11; the sixth point's falls on the
# first 30 scenes at N = 8 (falls30.json)
for m in p_s_dagger150_aug_mpa_r2_ce1 p_s_dagger150_aug_mpa_r2_ce1_seed1 p_s_dagger115_aug_mpa_r2_ce1_seed1 \
    p_s_dagger150_aug_mpa_r2_ce1_avg4; do
  [ -f $M/$m.zip ] || bash results/distill_scaling/run.sh
  .venv/bin/shelf-evaluate --policies $M/$m.zip --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb \
    --out results/distill_test "$@"
done
.venv/bin/python -m shelf_env.evaluation.falls $M/p_s_dagger150_aug_mpa_r2_ce1.zip --ns 8 --runs 30 --seed 0 \
  --out results/distill_test/falls30.json
# the ninth session: the seventh point (all 256 shards at its start), plain and with averaged weights (adopted on the
# validation scenes: results/distill_scaling/val90_averaging.md), on the same 90 scenes per N; falls at N = 8 on 30;
# the eleventh: the eighth point (all 324 shards at its start), averaged and plain, the same way
for m in p_s_dagger201_aug_mpa_r2_ce1 p_s_dagger201_aug_mpa_r2_ce1_avg4 p_s_dagger269_aug_mpa_r2_ce1_avg4 \
    p_s_dagger269_aug_mpa_r2_ce1; do
  [ -f $M/$m.zip ] || bash results/distill_scaling/run.sh
  .venv/bin/shelf-evaluate --policies $M/$m.zip --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb \
    --out results/distill_test "$@"
  .venv/bin/python -m shelf_env.evaluation.falls $M/$m.zip --ns 8 --runs 30 --seed 0 --out results/distill_test/falls30.json
done
# ... the eighth point's seed-1 replicate (plain), SR only
[ -f $M/p_s_dagger269_aug_mpa_r2_ce1_seed1.zip ] || bash results/distill_scaling/run.sh
.venv/bin/shelf-evaluate --policies $M/p_s_dagger269_aug_mpa_r2_ce1_seed1.zip --ns 5,8,11 --runs 30 --seeds 3 \
  --object-sets ycb --out results/distill_test "$@"
# ... and the shipped model (the ninth session's averaged one) under the loop breaker
.venv/bin/shelf-evaluate --policies $M/p_s_dagger201_aug_mpa_r2_ce1_avg4.zip+loop-breaker --ns 5,8,11 --runs 30 \
  --seeds 3 --object-sets ycb --out results/distill_test "$@"
b=p_s_dagger201_aug_mpa_r2_ce1_avg4
.venv/bin/python -m shelf_env.evaluation.compare results/distill_test --pair "$b+loop-breaker" $b \
  --pair "$b+loop-breaker" h-d --pair "$b+loop-breaker" h-a --pair "$b+loop-breaker" h-d+loop-breaker \
  --pair "$b+loop-breaker" h-a+loop-breaker --out results/distill_test/paired_loop_breaker.md
# the twelfth session: the ninth point (all 344 shards at its start), plain and averaged, the same way; the thirteenth:
# its seed-1 and seed-2 replicates (plain: the curve's points)
for m in p_s_dagger289_aug_mpa_r2_ce1 p_s_dagger289_aug_mpa_r2_ce1_avg4 p_s_dagger289_aug_mpa_r2_ce1_seed1 \
    p_s_dagger289_aug_mpa_r2_ce1_seed2; do
  [ -f $M/$m.zip ] || bash results/distill_scaling/run.sh
  .venv/bin/shelf-evaluate --policies $M/$m.zip --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb \
    --out results/distill_test "$@"
  .venv/bin/python -m shelf_env.evaluation.falls $M/$m.zip --ns 8 --runs 30 --seed 0 --out results/distill_test/falls30.json
done
# the curve's points distilled from every shard at a session's start, plain (the curve reads them): the tenth (the
# fifteenth session, 430 shards), the eleventh (the nineteenth, 649), the twelfth (the twenty-sixth, 1,438) and its
# seed-1 and seed-2 replicates (the twenty-seventh session on)
for m in p_s_dagger375_aug_mpa_r2_ce1 p_s_dagger594_aug_mpa_r2_ce1 p_s_dagger1383_aug_mpa_r2_ce1 \
    p_s_dagger1383_aug_mpa_r2_ce1_seed1 p_s_dagger1383_aug_mpa_r2_ce1_seed2; do
  [ -f $M/$m.zip ] || bash results/distill_scaling/run.sh
  .venv/bin/shelf-evaluate --policies $M/$m.zip --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb \
    --out results/distill_test "$@"
  .venv/bin/python -m shelf_env.evaluation.falls $M/$m.zip --ns 8 --runs 30 --seed 0 \
    --out results/distill_test/falls30.json
done
# ... and the P+S shipped in the twelfth session (the eleventh's seed-1 averaged model): its cells at N = 5, 8, 11 from
# its §V grid (results/models_v3, the same scenes), its falls at N = 8 as every point's
s1=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4=examples/pretrained/p_s.zip
.venv/bin/shelf-evaluate --policies "$s1" --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb --out results/distill_test \
  --reuse-cells results/models_v3/open "$@"
.venv/bin/python -m shelf_env.evaluation.falls "$s1" --ns 8 --runs 30 --seed 0 --out results/distill_test/falls30.json
# ... (thirteenth session) and its falls at N = 8 under the loop breaker
.venv/bin/python -m shelf_env.evaluation.falls "$s1+loop-breaker" --ns 8 --runs 30 --seed 0 \
  --out results/distill_test/falls30.json
# every policy's cells aggregated into results.json / results.csv / the plot (each run above wrote its own only)
.venv/bin/shelf-evaluate --policies "$d" "$d+loop-breaker" "$ps+loop-breaker" "$ps" examples/pretrained/s.zip h-d h-a \
  h-d+loop-breaker h-a+loop-breaker $M/p_s_d52sh_aug_mpa.zip $M/p_s_dagger7_aug_mpa.zip $M/p_s_dagger7_aug_mpa_r2_ce1.zip \
  $M/p_s_dagger19_aug_mpa_r2_ce1.zip $M/p_s_dagger48_aug_mpa_r2_ce1.zip $M/p_s_dagger75_aug_mpa_r2_ce1.zip $FT \
  $M/p_s_dagger115_aug_mpa_r2_ce1.zip $FT2 $M/p_s_dagger115_aug_mpa_r2_ce1.zip+loop-breaker $FT2+loop-breaker \
  $M/p_s_dagger150_aug_mpa_r2_ce1.zip $M/p_s_dagger150_aug_mpa_r2_ce1_seed1.zip $M/p_s_dagger115_aug_mpa_r2_ce1_seed1.zip \
  $M/p_s_dagger150_aug_mpa_r2_ce1_avg4.zip $M/p_s_dagger201_aug_mpa_r2_ce1.zip $M/p_s_dagger201_aug_mpa_r2_ce1_avg4.zip \
  $M/p_s_dagger269_aug_mpa_r2_ce1.zip $M/p_s_dagger269_aug_mpa_r2_ce1_avg4.zip $M/p_s_dagger269_aug_mpa_r2_ce1_seed1.zip \
  $M/p_s_dagger201_aug_mpa_r2_ce1_avg4.zip+loop-breaker $M/p_s_dagger289_aug_mpa_r2_ce1.zip \
  $M/p_s_dagger289_aug_mpa_r2_ce1_avg4.zip "$s1" $M/p_s_dagger289_aug_mpa_r2_ce1_seed1.zip \
  $M/p_s_dagger289_aug_mpa_r2_ce1_seed2.zip $M/p_s_dagger375_aug_mpa_r2_ce1.zip $M/p_s_dagger594_aug_mpa_r2_ce1.zip \
  $M/p_s_dagger1383_aug_mpa_r2_ce1.zip $M/p_s_dagger1383_aug_mpa_r2_ce1_seed1.zip \
  $M/p_s_dagger1383_aug_mpa_r2_ce1_seed2.zip --ns 5,8,11 --runs 30 --seeds 1 \
  --object-sets ycb --out results/distill_test --summarize-only
# the held-out scaling curve: falls and SR on the first 10 scenes per N (falls.json), and each model's SR and
# margin over the better heuristic on every evaluation scene it played (90 per N for the cross-entropy models)
.venv/bin/python research/scaling_curve.py results/distill_test --reports results/distill_scaling \
  --evaluation results/distill_test --out results/distill_test/scaling.md --png results/distill_test/scaling.png
# ... and every model's margin over the best heuristic variant, bare or under the loop breaker (like with like)
.venv/bin/python research/scaling_curve.py results/distill_test --reports results/distill_scaling \
  --evaluation results/distill_test --heuristics h-d h-a h-d+loop-breaker h-a+loop-breaker \
  --out results/distill_test/scaling_loop_breaker.md
for m in p_s_d52sh_aug_mpa p_s_dagger7_aug_mpa p_s_dagger7_aug_mpa_r2_ce1 p_s_dagger19_aug_mpa_r2_ce1 \
    p_s_dagger48_aug_mpa_r2_ce1 p_s_dagger75_aug_mpa_r2_ce1 p_s_dagger115_aug_mpa_r2_ce1 p_s_dagger150_aug_mpa_r2_ce1; do
  .venv/bin/python -m shelf_env.evaluation.report results/distill_test --learned $m --pick-only s --heuristics h-d h-a \
    --out results/distill_test/report_$m.md
done
