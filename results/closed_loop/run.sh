#!/usr/bin/env bash
# Issue 13's fall table: H-a and H-d (and the shipped P+S model when it exists) on N = 3..14 YCB,
# 30 runs x 3 seeds (issue 10's grid), open loop vs closed loop (the watch's defaults), the same
# scenes. Resumable; extra arguments go to shelf-evaluate. The open-loop cells are those of issue
# 10's evaluation (scripts/evaluate_models.sh, results/models), copied (--reuse-cells) instead of
# run again: the same scenes, but played on other machines (PyBullet differs by CPU; see the
# README), so compare with care or delete results/closed_loop/off/cells to run them here.
# results/closed_loop_seed0/run.sh is the two-core version (seed 0, N = 3, 5, 8, 11, 14, everything on
# one machine).
#   PS_SEEDS=1 bash results/closed_loop/run.sh --workers 2   # what was run on two cores: P+S on seed 0 only
# PS=0 leaves P+S out; PS_SEEDS (default 3) is the number of seeds P+S is evaluated on (a closed-loop
# episode of it costs ~4x a heuristic's). NAME (default on_deeper) names the closed-loop folder and
# WATCH (JSON, default the watch's defaults) its DragWatch fields; SAFE=1 adds --safe-picks to the
# closed-loop runs (not to the open-loop ones). Writes NAME_table.md (H-a, H-d),
# NAME_table_p_s.md (P+S on its seeds), NAME_table_p_s_vs_heuristics.md (all three on P+S's
# seeds) and the NAME_*.png plots.
# The committed folders: on (WATCH='{"place_check": false}', the defaults before the place check; its
# tables and plots are table.md, table_p_s.md and fell_rate / sr / loop_rate.png) and on_deeper_safe
# (the defaults with safe picks, issue 13's recommended setting: SAFE=1 NAME=on_deeper_safe
# PS_SEEDS=1 bash results/closed_loop/run.sh --workers 2, ~85 min for its 48 cells at N = 7..14
# on two cores). results/closed_loop_seed0/run.sh has the defaults on seed 0.
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
grid=(--ns 3-14 --runs 30 --object-sets ycb)
reuse=()
[ -d results/models/cells ] && reuse=(--reuse-cells results/models)
ps=examples/pretrained/v1/p_s.zip
ps_seeds=${PS_SEEDS:-3}
name=${NAME:-on_deeper}
loop=(--closed-loop "${WATCH:-"{}"}")
[ "${SAFE:-0}" = 1 ] && loop+=(--safe-picks)
out=results/closed_loop/$name
shelf-evaluate --policies h-a h-d "${grid[@]}" --seeds 3 --out results/closed_loop/off "${reuse[@]}" "$@"
shelf-evaluate --policies h-a h-d "${grid[@]}" --seeds 3 "${loop[@]}" --out "$out" "$@"
policies=(h-a h-d)
if [ "${PS:-1}" = 1 ] && [ -f "$ps" ]; then
  shelf-evaluate --policies "$ps" "${grid[@]}" --seeds "$ps_seeds" --out results/closed_loop/off "${reuse[@]}" "$@"
  shelf-evaluate --policies "$ps" "${grid[@]}" --seeds "$ps_seeds" "${loop[@]}" --out "$out" "$@"
  policies+=("$ps")
fi
# one summary (results.csv, results.json) of every cell in each folder
shelf-evaluate --policies "${policies[@]}" "${grid[@]}" --seeds 3 --out results/closed_loop/off --summarize-only
shelf-evaluate --policies "${policies[@]}" "${grid[@]}" --seeds 3 "${loop[@]}" --out "$out" --summarize-only
python research/closed_loop_table.py results/closed_loop/off "$out" --policies h-a h-d \
    --out "results/closed_loop/${name}_table.md"
if [ "${#policies[@]}" = 3 ]; then
  mapfile -t ps_seed_list < <(seq 0 $((ps_seeds - 1)))
  python research/closed_loop_table.py results/closed_loop/off "$out" --policies p_s --seeds "${ps_seed_list[@]}" \
      --out "results/closed_loop/${name}_table_p_s.md"
  # P+S beside the heuristics on the same seeds (its seeds), both loops
  python research/closed_loop_table.py results/closed_loop/off "$out" --policies h-a h-d p_s \
      --seeds "${ps_seed_list[@]}" --out "results/closed_loop/${name}_table_p_s_vs_heuristics.md"
fi
for metric in fell_rate sr loop_rate; do
  python research/plot_conditions.py --metric $metric --x n --runs results/closed_loop/off:off \
      "$out:$name" --out "results/closed_loop/${name}_${metric}.png"
done
