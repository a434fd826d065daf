#!/usr/bin/env bash
# Issue 13's robustness curves: SR against perception-noise level at N = 5 and 8, YCB, for H-a, H-d
# and the best learned P+S checkpoint available (examples/pretrained/v1/p_s.zip, else the recipe's
# N = 3 checkpoint), the same scenes at every level. Level L means dropout = part_dropout =
# class_flip = L and depth_sigma = L cm. Resumable (each level is its own shelf-evaluate folder);
# extra arguments go to shelf-evaluate (e.g. --workers 16, --backend ray).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
learned=examples/pretrained/v1/p_s.zip
[ -f "$learned" ] || learned=results/learning/recipe_n3.zip
runs=()
for level in 0 0.05 0.1 0.2 0.3; do
  noise="{\"dropout\": $level, \"part_dropout\": $level, \"class_flip\": $level, \"depth_sigma\": $(python -c "print($level / 100)")}"
  shelf-evaluate --policies h-a h-d "$learned" --ns 5,8 --runs 20 --seeds 2 --object-sets ycb \
      --perception-noise "$noise" --out "results/robustness/level_$level" "$@"
  runs+=("results/robustness/level_$level:$level")
done
python research/plot_conditions.py --metric sr --x condition --ns 5 8 --runs "${runs[@]}" \
    --out results/robustness/sr_vs_noise.png
