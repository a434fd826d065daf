#!/usr/bin/env bash
# Named fall geometry against the learned fall model (docs/experiments/fall-geometry.md):
#   1. per labelled pick of the fall model's split (results/teacher_fall_filter's 374 shards, the last 20 % of each
#      series' scenes held out) and of a test set no fall model read (the shards s03_00054..94 and s04_00010..58):
#      the named features (round one) -> features.npz, and with the blocker features (round two)
#      -> features_blockers.npz
#   2. per feature set: a logistic regression and an MLP, each feature's own AUC, the features joined to the
#      from-scratch fall model (two-fold by scene) and averaged with it (ensemble), on the validation split and on
#      the test set, with the offline check of the shipped P+S's choice among the labelled picks
#      -> fit.json, fit_blockers.json (and their .models.pt)
# Each step skips what is on disk.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
export OMP_NUM_THREADS=1
out=results/fall_geometry
shards=s00:55,s01:50,s02:205,s03:54,s04:10
fresh=s03:95,s04:59
fall_model=results/teacher_fall_filter/scratch/ff_scratch.fall_risk.pt
for set in "" _blockers; do
    flag=${set:+--blockers}
    [ -f "$out/features$set.npz" ] || python -m research.fall_geometry features --data data/teacher \
        --max-shards "$shards" --val-fraction 0.2 --fresh "$fresh" $flag --out "$out/features$set.npz"
    [ -f "$out/fit$set.json" ] || python -m research.fall_geometry fit --data data/teacher --max-shards "$shards" \
        --val-fraction 0.2 --fresh "$fresh" --features "$out/features$set.npz" --fall-model "$fall_model" \
        --checkpoint examples/pretrained/p_s.zip --out "$out/fit$set.json"
done
# 3. round three: the fall model's recipe from scratch with round two's features as 36 more input channels
#    -> ff_channels.fall_risk.pt, channels.json
[ -f "$out/channels.json" ] || python -m research.fall_geometry channels --data data/teacher --max-shards "$shards" \
    --val-fraction 0.2 --fresh "$fresh" --features "$out/features_blockers.npz" --fall-model "$fall_model" \
    --checkpoint examples/pretrained/p_s.zip --out "$out/ff_channels.fall_risk.pt" --report "$out/channels.json"
# 4. (added after round two's numbers) round two's MLP as a mask at 0.1 on the shipped P+S, on the validation scenes
#    (seeds 2000-2002, N = 5, 8, 11); the shipped model's cells reused -> filter/, val90/, val90_pairs.md
mkdir -p "$out/filter"
cp -p examples/pretrained/p_s.zip "$out/filter/p_s_geo10.zip"
[ -f "$out/filter/p_s_geo10.geometry_risk.pt" ] || python -m research.fall_geometry export \
    --models "$out/fit_blockers.models.pt" --name mlp --features "$out/features_blockers.npz" --threshold 0.1 \
    --out "$out/filter/p_s_geo10.geometry_risk.pt"
ref=p_s_dagger269_aug_mpa_r2_ce1_seed1_avg4
python -m research.evaluate --policies "$out/filter/p_s_geo10.zip+geometry-filter" "$ref=examples/pretrained/p_s.zip" \
    --ns 5,8,11 --runs 30 --seeds 3 --first-seed 2000 --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90" \
    --reuse-cells results/distill_scaling/val90
python -m shelf_env.evaluation.compare "$out/val90" --pair p_s_geo10+geometry-filter "$ref" --out "$out/val90_pairs.md"
# 5. (added after the validation numbers) the same filter, unchanged, on issue 10's held-out cells at N = 5, 8, 11
#    (seeds 0-2) beside the shipped P+S, S, H-d and H-a (their cells from results/models_v3/open), and its greedy fall
#    rate per action at N = 8 on the first 30 held-out scenes -> heldout/, heldout_pairs.md, falls30.json
python -m research.evaluate --policies "$out/filter/p_s_geo10.zip+geometry-filter" "$ref=examples/pretrained/p_s.zip" \
    examples/pretrained/s.zip h-d h-a --ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb --workers "${WORKERS:-1}" \
    --out "$out/heldout" --reuse-cells results/models_v3/open
python -m shelf_env.evaluation.compare "$out/heldout" --pair p_s_geo10+geometry-filter "$ref" \
    --pair p_s_geo10+geometry-filter h-a --pair p_s_geo10+geometry-filter h-d --out "$out/heldout_pairs.md"
[ -f "$out/falls30.json" ] || python -c "import research.fall_geometry, sys; from shelf_env.evaluation.falls import main; \
sys.exit(main(sys.argv[1:]))" "$out/filter/p_s_geo10.zip+geometry-filter" --ns 8 --runs 30 --seed 0 --out "$out/falls30.json"
# 6. (added after the held-out numbers) the filter, then the loop breaker, on the validation scenes -> val90_lb/,
#    val90_lb_pairs.md (the filter alone's and the shipped model's cells copied from val90/)
python -m research.evaluate --policies "$out/filter/p_s_geo10.zip+geometry-filter+loop-breaker" \
    "$out/filter/p_s_geo10.zip+geometry-filter" "$ref=examples/pretrained/p_s.zip" --ns 5,8,11 --runs 30 --seeds 3 \
    --first-seed 2000 --object-sets ycb --workers "${WORKERS:-1}" --out "$out/val90_lb" --reuse-cells "$out/val90"
python -m shelf_env.evaluation.compare "$out/val90_lb" --pair p_s_geo10+geometry-filter+loop-breaker \
    p_s_geo10+geometry-filter --pair p_s_geo10+geometry-filter+loop-breaker "$ref" --out "$out/val90_lb_pairs.md"
# 7. (added after the validation numbers of 6) the filter with the loop breaker on the held-out cells, beside the
#    filter alone, the shipped P+S, S, H-d, H-a (from heldout/) and H-d, H-a with the loop breaker (from
#    results/distill_test) -> heldout_lb/, heldout_lb_pairs.md
lb="$out/filter/p_s_geo10.zip+geometry-filter+loop-breaker"
grid=(--ns 5,8,11 --runs 30 --seeds 3 --object-sets ycb --workers "${WORKERS:-1}" --out "$out/heldout_lb")
python -m research.evaluate --policies "$lb" "${grid[@]}"
python -m research.evaluate --policies "$out/filter/p_s_geo10.zip+geometry-filter" "$ref=examples/pretrained/p_s.zip" \
    examples/pretrained/s.zip h-d h-a "${grid[@]}" --reuse-cells "$out/heldout"
python -m research.evaluate --policies h-d+loop-breaker h-a+loop-breaker "${grid[@]}" --reuse-cells results/distill_test
python -m research.evaluate --policies "$lb" "$out/filter/p_s_geo10.zip+geometry-filter" "$ref=examples/pretrained/p_s.zip" \
    examples/pretrained/s.zip h-d h-a h-d+loop-breaker h-a+loop-breaker "${grid[@]}" --summarize-only
l=p_s_geo10+geometry-filter+loop-breaker
python -m shelf_env.evaluation.compare "$out/heldout_lb" --pair $l "$ref" --pair $l p_s_geo10+geometry-filter \
    --pair $l h-a --pair $l h-d --pair $l h-a+loop-breaker --pair $l h-d+loop-breaker --out "$out/heldout_lb_pairs.md"
# 8-10. (the seventeenth session) the filter + loop breaker on the whole §V grid, open loop and closed loop + safe
#    picks, and the shipped P+S with the loop breaker alone: sv.sh
bash "$out/sv.sh"
python - "$out" <<'PY'
import json, sys
for name in ("fit", "fit_blockers"):
    r = json.load(open(f"{sys.argv[1]}/{name}.json"))
    print(f"{name}: validation MLP {r['mlp']['val_auc']:.3f} (epoch {r['mlp']['best_epoch']}), logistic "
          f"{r['logistic']['val_auc']:.3f}, fall model {r['twofold']['fcn']:.3f}, ensemble {r['ensemble']:.3f}; "
          f"test " + ", ".join(f"{k} {v:.3f}" for k, v in r["test"].items() if k not in ("labels", "invalid")))
    for where in ("offline", "test_offline"):
        o = r[where]
        print(f"  {where}: unfiltered {100 * o['unfiltered']['invalid']:.1f} % / {o['unfiltered']['sorted']:.3f}, "
              f"candidate {o['candidate']}")
c = json.load(open(f"{sys.argv[1]}/channels.json"))
print(f"channels: validation {c['val_auc']:.3f} (epoch {c['best_epoch']}), test {c['test_auc']:.3f}; the fall model "
      f"{c['val_fcn_auc']:.3f} / {c['test_fcn_auc']:.3f}; candidate on validation {c['val_offline']['candidate']}")
PY
cat "$out/val90_pairs.md" "$out/heldout_pairs.md" "$out/val90_lb_pairs.md" "$out/heldout_lb_pairs.md" \
    "$out/sv_open/paired.md" "$out/heldout_plb_pairs.md" "$out/sv_closed_safe/paired.md"
