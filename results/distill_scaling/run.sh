#!/usr/bin/env bash
# Distilling the teacher dataset into the shipped P+S (docs/experiments/distill-scaling.md): four recipes,
# each from the first 220, 440 and all training states of the dataset's first 35 shards (70 scenes; the
# last 20 % of the scenes are the distillation's validation states), then each model's greedy actions
# that would end the episode invalid, per action, and its greedy SR at N = 8, 5, 11 on validation scenes
# (evaluation seed 2000, YCB), beside the shipped P+S and H-d.
#   bash results/distill_scaling/run.sh     # distil (2-3 min a model, one thread) and measure (resumable)
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
PY=${PYTHON:-.venv/bin/python}
DIR=results/distill_scaling
M=runs/distill_scaling
mkdir -p "$M"

distil() {  # NAME STATES OPTIONS...: STATES "all" or a number of training states; SHARDS (default 35) the shards
  local name=$1 states=$2
  shift 2
  local extra=()
  [ "$states" != all ] && extra=(--max-states "$states")
  if [ ! -f "$M/$name.zip" ]; then
    "$PY" -m shelf_env.training.distill --data data/teacher --max-shards "${SHARDS:-35}" "${extra[@]}" \
      --init examples/pretrained/v1/p_s.zip --out "$M/$name.zip" --epochs 8 --val-fraction 0.2 "$@"
  fi
  cp "$M/$name.distill.json" "$DIR/$name.distill.json"
}

for n in 220 440 all; do
  # A: the states as stored, the teacher's margin over its labelled actions (the first loss)
  distil "p_s_d$n" "$n" --no-augment --teacher-over labelled --no-progress
  # D: + augmentation, the margin over every allowed action, the progress term, the anchor
  distil "p_s_d${n}_aug_mpa" "$n" --anchor 1.0
done
for n in 220 440; do  # C without the anchor
  distil "p_s_d${n}_aug_mp" "$n"
done
distil p_s_dall_aug all --teacher-over labelled --no-progress  # A + augmentation
distil p_s_dall_aug_m all --no-progress                         # + the margin over every allowed action
distil p_s_dall_aug_mp all                                      # C: + the progress term

# The first 52 shards (104 scenes: 1,325 training states; the last 21 scenes validation): D, and D with the
# teacher's action standing for its 5 x 5-cell square (radius 2), then also weighted 5, then for 24 epochs;
# D with the progress term's lower action standing for its square
SHARDS=52 distil p_s_d52sh_aug_mpa all --anchor 1.0
SHARDS=52 distil p_s_d52sh_aug_mpa_r2 all --anchor 1.0 --teacher-radius 2
SHARDS=52 distil p_s_d52sh_aug_mpa_r2_t5 all --anchor 1.0 --teacher-radius 2 --teacher-weight 5
SHARDS=52 distil p_s_d52sh_aug_mpa_r2_t5_e24 all --anchor 1.0 --teacher-radius 2 --teacher-weight 5 --epochs 24
SHARDS=52 distil p_s_d52sh_aug_mpa_pr2 all --anchor 1.0 --progress-radius 2  # D, a useless action's square pushed down
# D from the first 55 shards of series 0 and the first 7 of series 1 (DAgger: driven by p_s_d52sh_aug_mpa, explore 1)
SHARDS=s00:55,s01:7 distil p_s_dagger7_aug_mpa all --anchor 1.0
SHARDS=s00:55,s01:7 distil p_s_dagger7_aug_mpa_pr2_p5 all --anchor 1.0 --progress-radius 2 --progress-weight 5
# ... with the teacher term as a cross-entropy of the allowed actions' softmax (temperature 1) on its 5 x 5 square
SHARDS=s00:55,s01:7 distil p_s_dagger7_aug_mpa_r2_ce1 all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1
# the cross-entropy recipe at the third session's dataset (55 shards of series 0, 19 of series 1): the scaling point
SHARDS=s00:55,s01:19 distil p_s_dagger19_aug_mpa_r2_ce1 all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1
# ... and at the fifth session's dataset (55 + 48 shards: 4,338 states, 3,626 of them for training): the next point
SHARDS=s00:55,s01:48 distil p_s_dagger48_aug_mpa_r2_ce1 all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1
# ... and at the sixth session's dataset (55 + 50 shards of series 1 + 25 of series 2, driven by the 3,626-state model)
SHARDS=s00:55,s01:50,s02:25 distil p_s_dagger75_aug_mpa_r2_ce1 all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1
# ... and at the seventh session's dataset (55 + 50 + 65 shards: 7,351 states, 6,242 of them for training): the fifth point
SHARDS=s00:55,s01:50,s02:65 distil p_s_dagger115_aug_mpa_r2_ce1 all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1
# ... and at the eighth session's dataset (all 205 shards at its start: 55 + 50 + 100): the sixth point
SHARDS=s00:55,s01:50,s02:100 distil p_s_dagger150_aug_mpa_r2_ce1 all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1
# ... the fifth and sixth points distilled again at seed 1 (the batch order and augmentation draws): how far apart two
# models from the same data land
SHARDS=s00:55,s01:50,s02:65 distil p_s_dagger115_aug_mpa_r2_ce1_seed1 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --seed 1
SHARDS=s00:55,s01:50,s02:100 distil p_s_dagger150_aug_mpa_r2_ce1_seed1 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --seed 1
# ... and the sixth point's data with the weights averaged over the last 4 epochs (one model from a stretch of
# training rather than the last step's draw), judged on the validation scenes (seed 2000, the first 30 at N = 8)
# beside the two plain models
SHARDS=s00:55,s01:50,s02:100 distil p_s_dagger150_aug_mpa_r2_ce1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --average-last 4
for m in p_s_dagger150_aug_mpa_r2_ce1_avg4 p_s_dagger150_aug_mpa_r2_ce1 p_s_dagger150_aug_mpa_r2_ce1_seed1; do
  "$PY" -m shelf_env.evaluation.falls "$M/$m.zip" --ns 8 --runs 30 --seed 2000 --out "$DIR/falls_val30.json"
done
"$PY" research/scaling_curve.py "$DIR" --falls falls_val30.json --out "$DIR/val30.md"
# The ninth session: averaging validated as the held-out grid is played. The sixth point's data at seed 1 with the
# weights averaged (its seed-0 twin is above); the four models on the validation scenes (evaluation seeds
# 2000-2002, 90 per N at N = 5, 8, 11), each averaged model against its own plain one on the same scenes
SHARDS=s00:55,s01:50,s02:100 distil p_s_dagger150_aug_mpa_r2_ce1_seed1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --seed 1 --average-last 4
b=p_s_dagger150_aug_mpa_r2_ce1
"$PY" -m shelf_env.cli.evaluate --policies "$M/${b}_avg4.zip" "$M/$b.zip" "$M/${b}_seed1_avg4.zip" "$M/${b}_seed1.zip" \
  --ns 5,8,11 --runs 30 --seeds 3 --first-seed 2000 --object-sets ycb --workers 1 --out "$DIR/val90"
"$PY" -m shelf_env.evaluation.compare "$DIR/val90" --pair "${b}_avg4" "$b" --pair "${b}_seed1_avg4" "${b}_seed1" \
  --out "$DIR/val90_averaging.md"
# (the session ran these with --last-out, each run saving the plain twin too: the same weights as the lines above)
# ... and the seventh point: all 256 shards at the ninth session's start (55 + 50 + 151), averaged and plain from one run
SHARDS=s00:55,s01:50,s02:151 distil p_s_dagger201_aug_mpa_r2_ce1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --average-last 4 --last-out "$M/p_s_dagger201_aug_mpa_r2_ce1.zip"
cp "$M/p_s_dagger201_aug_mpa_r2_ce1.distill.json" "$DIR/"

# B + 45 min of PixelDoubleDQN with the dataset as demonstrations (the data/teacher of the time: 37 shards)
if [ ! -f "$M/p_s_dall_aug_m_ft45.zip" ]; then
  bash results/distill_finetune/train.sh 0.75 "$M/p_s_dall_aug_m.zip" runs/distill_finetune
  cp runs/distill_finetune/model.zip "$M/p_s_dall_aug_m_ft45.zip"
fi

ps=examples/pretrained/v1/p_s.zip
"$PY" -m shelf_env.evaluation.falls "$ps" "$M/p_s_dall_aug_m_ft45.zip" "$M/p_s_dall_aug_mpa.zip" \
  "$M/p_s_dall_aug_mpa.zip+loop-breaker" "$ps+loop-breaker" "$M/p_s_d440_aug_mpa.zip" "$M/p_s_d220_aug_mpa.zip" \
  "$M/p_s_dall_aug_mp.zip" "$M/p_s_dall_aug_mp.zip+loop-breaker" "$M/p_s_d440_aug_mp.zip" "$M/p_s_d220_aug_mp.zip" \
  h-d "$M/p_s_dall_aug.zip" "$M/p_s_dall_aug_m.zip" "$M/p_s_dall.zip" "$M/p_s_d440.zip" "$M/p_s_d220.zip" \
  --ns 8 --runs 10 --seed 2000 --out "$DIR/falls.json"
"$PY" -m shelf_env.evaluation.falls "$ps" "$M/p_s_dall_aug_mpa.zip" "$M/p_s_dall_aug_mpa.zip+loop-breaker" \
  "$ps+loop-breaker" h-d --ns 5 11 --runs 10 --seed 2000 --out "$DIR/falls.json"
"$PY" -m shelf_env.evaluation.falls "$M/p_s_d52sh_aug_mpa.zip" "$M/p_s_d52sh_aug_mpa_r2.zip" \
  "$M/p_s_d52sh_aug_mpa_r2_t5.zip" "$M/p_s_d52sh_aug_mpa_r2_t5_e24.zip" "$M/p_s_d52sh_aug_mpa_pr2.zip" \
  "$M/p_s_dagger7_aug_mpa.zip" "$M/p_s_dagger7_aug_mpa_pr2_p5.zip" "$M/p_s_dagger7_aug_mpa_r2_ce1.zip" --ns 8 --runs 10 --seed 2000 --out "$DIR/falls.json"
"$PY" research/scaling_curve.py "$DIR" --out "$DIR/report.md" --png "$DIR/scaling.png"
# The eleventh session: the eighth point, all 324 shards at its start (55 + 50 + 205 + 14 of series 3), averaged
# and plain from one run; then two model soups (research/model_soup.py) and every ingredient's distillation loss on
# the eighth run's validation states, which none of them trained on (soups_val_loss.jsonl)
SHARDS=s00:55,s01:50,s02:205,s03:14 distil p_s_dagger269_aug_mpa_r2_ce1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --average-last 4 --last-out "$M/p_s_dagger269_aug_mpa_r2_ce1.zip"
cp "$M/p_s_dagger269_aug_mpa_r2_ce1.distill.json" "$DIR/"
# ... and its replicate at distillation seed 1 (the plain model is the curve's second point at 11,356 states)
SHARDS=s00:55,s01:50,s02:205,s03:14 distil p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --average-last 4 --seed 1 --last-out "$M/p_s_dagger269_aug_mpa_r2_ce1_seed1.zip"
cp "$M/p_s_dagger269_aug_mpa_r2_ce1_seed1.distill.json" "$DIR/"
V=(--val-shards s00:55,s01:50,s02:205,s03:14 --teacher-radius 2 --teacher-temperature 1)
a=(p_s_dagger201_aug_mpa_r2_ce1_avg4 p_s_dagger269_aug_mpa_r2_ce1_avg4)
b=(p_s_dagger150_aug_mpa_r2_ce1_avg4 p_s_dagger150_aug_mpa_r2_ce1_seed1_avg4 "${a[@]}")
{
  "$PY" research/model_soup.py "${a[@]/#/$M/}" --out "$M/p_s_soup_a.zip" "${V[@]}"
  "$PY" research/model_soup.py "${b[@]/#/$M/}" --out "$M/p_s_soup_b.zip" "${V[@]}"
} > "$DIR/soups_val_loss.jsonl"
cp "$M/p_s_soup_a.soup.json" "$M/p_s_soup_b.soup.json" "$DIR/"
# ... the seed-1 run's averaged model (the replicate's held-out row was 6.7 points above seed 0's) against the shipped
# model on the validation scenes (evaluation seeds 2000-2002, 90 per N at N = 5, 8, 11): the rule in the page
for m in p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 p_s_dagger201_aug_mpa_r2_ce1_avg4; do
  "$PY" -m shelf_env.cli.evaluate --policies "$M/$m.zip" --ns 5,8,11 --runs 30 --seeds 3 --first-seed 2000 \
    --object-sets ycb --workers 1 --out "$DIR/val90"
done
"$PY" -m shelf_env.evaluation.compare "$DIR/val90" --pair p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 \
  p_s_dagger201_aug_mpa_r2_ce1_avg4 --out "$DIR/val90_seed1.md"

# The twelfth session: the ninth point, all 344 shards at its start (55 + 50 + 205 + 34 of series 3), averaged and
# plain from one run
SHARDS=s00:55,s01:50,s02:205,s03:34 distil p_s_dagger289_aug_mpa_r2_ce1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --average-last 4 --last-out "$M/p_s_dagger289_aug_mpa_r2_ce1.zip"
cp "$M/p_s_dagger289_aug_mpa_r2_ce1.distill.json" "$DIR/"
# The thirteenth session: the ninth point's data again at seeds 1 and 2 (three seeds at 12,206 training states), then
# the two averaged models on the validation scenes (evaluation seeds 2000-2002, 90 per N at N = 5, 8, 11) against the
# shipped model's cells there (the eleventh session's seed-1 averaged model, val90): the rule in the page
for s in 1 2; do
  SHARDS=s00:55,s01:50,s02:205,s03:34 distil "p_s_dagger289_aug_mpa_r2_ce1_seed${s}_avg4" all --anchor 1.0 \
    --teacher-radius 2 --teacher-temperature 1 --average-last 4 --seed "$s" \
    --last-out "$M/p_s_dagger289_aug_mpa_r2_ce1_seed$s.zip"
  cp "$M/p_s_dagger289_aug_mpa_r2_ce1_seed$s.distill.json" "$DIR/"
  "$PY" -m shelf_env.cli.evaluate --policies "$M/p_s_dagger289_aug_mpa_r2_ce1_seed${s}_avg4.zip" --ns 5,8,11 --runs 30 \
    --seeds 3 --first-seed 2000 --object-sets ycb --workers 1 --out "$DIR/val90"
done
# ... and the three seeds' averaged models as one QEnsemble (greedy on the mean of their Q-maps), the same scenes, beside
# its third member (seed 0, the ninth point's averaged model) alone
"$PY" -m shelf_env.cli.evaluate --policies "$M/p_s_dagger289_aug_mpa_r2_ce1_avg4.zip" --ns 5,8,11 --runs 30 --seeds 3 \
  --first-seed 2000 --object-sets ycb --workers 1 --out "$DIR/val90"
E=p_s_dagger289_aug_mpa_r2_ce1_ens3_avg4
"$PY" -c "import sys; from shelf_env.policies import write_ensemble; write_ensemble(sys.argv[1], sys.argv[2:])" \
  "$M/$E.ensemble.json" "$M/p_s_dagger289_aug_mpa_r2_ce1_avg4.zip" "$M/p_s_dagger289_aug_mpa_r2_ce1_seed1_avg4.zip" \
  "$M/p_s_dagger289_aug_mpa_r2_ce1_seed2_avg4.zip"
"$PY" -m shelf_env.cli.evaluate --policies "$M/$E.ensemble.json" --ns 5,8,11 --runs 30 --seeds 3 --first-seed 2000 \
  --object-sets ycb --workers 1 --out "$DIR/val90"
"$PY" -m shelf_env.evaluation.compare "$DIR/val90" --pair p_s_dagger289_aug_mpa_r2_ce1_seed1_avg4 \
  p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 --pair p_s_dagger289_aug_mpa_r2_ce1_seed2_avg4 \
  p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 --pair $E p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 \
  --pair $E p_s_dagger289_aug_mpa_r2_ce1_avg4 --pair $E p_s_dagger289_aug_mpa_r2_ce1_seed1_avg4 \
  --pair $E p_s_dagger289_aug_mpa_r2_ce1_seed2_avg4 \
  --out "$DIR/val90_seeds.md"
# The fifteenth session: the tenth point, all 430 shards at its start (55 + 50 + 205 + 80 of series 3 + 40 of series 4),
# averaged and plain from one run
SHARDS=s00:55,s01:50,s02:205,s03:80,s04:40 distil p_s_dagger375_aug_mpa_r2_ce1_avg4 all --anchor 1.0 --teacher-radius 2 \
  --teacher-temperature 1 --average-last 4 --last-out "$M/p_s_dagger375_aug_mpa_r2_ce1.zip"
cp "$M/p_s_dagger375_aug_mpa_r2_ce1.distill.json" "$DIR/"
# ... its averaged model on the validation scenes (evaluation seeds 2000-2002, 90 per N at N = 5, 8, 11): the page's rule
"$PY" -m shelf_env.cli.evaluate --policies "$M/p_s_dagger375_aug_mpa_r2_ce1_avg4.zip" --ns 5,8,11 --runs 30 --seeds 3 \
  --first-seed 2000 --object-sets ycb --workers 2 --out "$DIR/val90"
"$PY" -m shelf_env.evaluation.compare "$DIR/val90" --pair p_s_dagger375_aug_mpa_r2_ce1_avg4 \
  p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 --out "$DIR/val90_tenth.md"
# every model's cells on the validation scenes aggregated into val90/results.json, results.csv and the plot
V90=(p_s_dagger150_aug_mpa_r2_ce1_avg4 p_s_dagger150_aug_mpa_r2_ce1 p_s_dagger150_aug_mpa_r2_ce1_seed1_avg4
  p_s_dagger150_aug_mpa_r2_ce1_seed1 p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4 p_s_dagger201_aug_mpa_r2_ce1_avg4
  p_s_dagger289_aug_mpa_r2_ce1_avg4 p_s_dagger289_aug_mpa_r2_ce1_seed1_avg4 p_s_dagger289_aug_mpa_r2_ce1_seed2_avg4
  p_s_dagger375_aug_mpa_r2_ce1_avg4)
P=()
for v in "${V90[@]}"; do P+=("$M/$v.zip"); done
"$PY" -m shelf_env.cli.evaluate --policies "${P[@]}" "$M/$E.ensemble.json" --ns 5,8,11 \
  --runs 30 --seeds 3 --first-seed 2000 --object-sets ycb --out "$DIR/val90" --summarize-only
# A curve point from every shard at a session's start: the averaged model and the plain one (the curve reads the plain
# one: results/distill_test/run.sh) from one run, the cross-entropy recipe, checkpointed each epoch into a resume file
# here (commit it when a session ends mid-run; the run goes on from it and removes it when done)
whole() {  # whole NAME SHARDS [OPTIONS...]: NAME the plain model, NAME_avg4 the averaged one; OPTIONS (--seed) to distil
  local name=$1 shards=$2
  shift 2
  SHARDS=$shards distil "${name}_avg4" all --anchor 1.0 --teacher-radius 2 --teacher-temperature 1 --average-last 4 \
    --last-out "$M/$name.zip" --resume-file "$DIR/${name}_avg4.resume.pt" "$@"
  cp "$M/$name.distill.json" "$DIR/"
}
# The nineteenth session: the eleventh point, all 649 shards at its start (55 + 50 + 205 + 184 of series 3 + 155 of
# series 4), distilled across two sessions
whole p_s_dagger594_aug_mpa_r2_ce1 s00:55,s01:50,s02:205,s03:184,s04:155
# The twenty-sixth session: the twelfth point, all 1,438 shards at its start (55 + 50 + 205 + 570 of series 3 + 172 of
# series 4 + 386 of series 5), the eleventh point's recipe unchanged
whole p_s_dagger1383_aug_mpa_r2_ce1 s00:55,s01:50,s02:205,s03:570,s04:172,s05:386
# The twenty-seventh session on: the twelfth point's seed-1 and seed-2 replicates (the same shards and recipe, another
# batch order and augmentation), as the ninth point's were
whole p_s_dagger1383_aug_mpa_r2_ce1_seed1 s00:55,s01:50,s02:205,s03:570,s04:172,s05:386 --seed 1
whole p_s_dagger1383_aug_mpa_r2_ce1_seed2 s00:55,s01:50,s02:205,s03:570,s04:172,s05:386 --seed 2
