#!/usr/bin/env bash
# A distilled model as a veto on the shipped P+S's choice (docs/experiments/distilled-veto.md): the shipped
# model chooses among the allowed actions the distilled model values within delta of its best.
#   1. the policies: a copy of p_s.zip per (veto model, delta) with its settings beside it (runs/distilled_veto/)
#   2. margins.json: what a veto at each delta keeps of the veto models' own validation labels
#   3. validation (seed 2000, N = 8, 10 scenes): greedy invalid actions per action and SR of each pair
#      -> falls_validation.json; the pair chosen there (p_s_vmpa_d025: the lowest invalid rate, the highest SR)
#   4. held out (the §V comparison's seed 0, N = 5, 8, 11, 30 scenes, open loop) beside the shipped P+S, S, H-d
#      and H-a (their cells copied from results/models) -> cells/, results.*, report.md; and its greedy invalid
#      actions per action on the first 10 of those scenes at N = 8 -> falls_test.json
# Resumable: each step skips what is on disk.
#   bash results/distilled_veto/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1
PY=.venv/bin/python
M=runs/distill_scaling
V=runs/distilled_veto
out=results/distilled_veto
[ -f $M/p_s_dall_aug_mp.zip ] && [ -f $M/p_s_dall_aug_mpa.zip ] || bash results/distill_scaling/run.sh
pairs=(mp:1 mp:0.5 mp:0.25 mpa:1 mpa:0.5 mpa:0.25)
for pair in "${pairs[@]}"; do
  m=${pair%%:*}; d=${pair#*:}
  $PY -m research.distilled_veto make --veto $M/p_s_dall_aug_$m.zip --delta "$d" --out "$V/p_s_v${m}_d${d/./}.zip"
done
[ -f $out/margins.json ] || $PY -m research.distilled_veto margins $M/p_s_dall_aug_mp.zip $M/p_s_dall_aug_mpa.zip \
  --out $out/margins.json
for pair in "${pairs[@]}"; do
  m=${pair%%:*}; d=${pair#*:}
  $PY -m research.distilled_veto falls "$V/p_s_v${m}_d${d/./}.zip+veto" --ns 8 --runs 10 --seed 2000 \
    --out $out/falls_validation.json
done
chosen=$V/p_s_vmpa_d025.zip
$PY -m research.evaluate --policies "$chosen+veto" examples/pretrained/v1/p_s.zip examples/pretrained/s.zip h-d h-a \
  --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb --out $out --reuse-cells results/models --workers 1
$PY -m research.distilled_veto falls "$chosen+veto" --ns 8 --runs 10 --seed 0 --out $out/falls_test.json
$PY -m shelf_env.evaluation.report $out --learned p_s_vmpa_d025+veto --pick-only s --heuristics h-d h-a
