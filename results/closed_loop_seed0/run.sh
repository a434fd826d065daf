#!/usr/bin/env bash
# Issue 13's fall table on two cores: H-a and H-d on seed 0's YCB scenes of issue 10's grid at
# N = 3, 5, 8, 11, 14 (30 runs each), and the shipped P+S model at N = 5, 8, 11 (PS=0 leaves it
# out), open loop vs closed loop, both run here so that every compared episode comes from one
# machine. Resumable; extra arguments go to shelf-evaluate.
#   bash results/closed_loop_seed0/run.sh --workers 2                       # the watch's defaults -> on_deeper/
#   WATCH='{"sustain": 2}' NAME=on_s2 bash results/closed_loop_seed0/run.sh  # a variant -> on_s2/
# The committed folders: on_deeper (the defaults: lane check, put back when blocked, place check
# placing a refused object again further in), on_place (WATCH='{"stacked": "put back"}'),
# on_lane_pb (WATCH='{"place_check": false}'), on_lane (WATCH='{"blocked": "carry", "place_check":
# false}', PS=0), on (WATCH='{"lane": false, "place_check": false}': the force and camera watches
# alone), on_s2 (on's with "sustain": 2, "threshold": 0.5, PS=0) and on_s2in (on_s2's with
# "judge_outside": false, PS=0); each conditions.json holds every field it ran with.
# on_lane_pb_safe and on_deeper_safe add --safe-picks (run with shelf-evaluate, see the README).
# results/closed_loop/run.sh is the full grid (N = 3..14, 3 seeds).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
name=${NAME:-on_deeper}
watch=${WATCH:-"{}"}
for out in off "$name"; do
  loop=()
  [ "$out" = off ] || loop=(--closed-loop "$watch")
  shelf-evaluate --policies h-a h-d --ns 3,5,8,11,14 --runs 30 --seeds 1 --object-sets ycb "${loop[@]}" \
      --out "results/closed_loop_seed0/$out" "$@"
  policies=(h-a h-d)
  # the shipped P+S model where it exists (N = 5, 8, 11: an episode of it costs ~4x a heuristic's)
  if [ "${PS:-1}" = 1 ] && [ -f examples/pretrained/v1/p_s.zip ]; then
    shelf-evaluate --policies examples/pretrained/v1/p_s.zip --ns 5,8,11 --runs 30 --seeds 1 --object-sets ycb \
        "${loop[@]}" --out "results/closed_loop_seed0/$out" "$@"
    policies+=(examples/pretrained/v1/p_s.zip)
  fi
  # one summary (results.json, results.csv) of every cell in the folder
  shelf-evaluate --policies "${policies[@]}" --ns 3,5,8,11,14 --runs 30 --seeds 1 --object-sets ycb \
      "${loop[@]}" --out "results/closed_loop_seed0/$out" --summarize-only
done
for metric in fell_rate sr; do
  python research/plot_conditions.py --metric $metric --x n --runs results/closed_loop_seed0/off:off \
      "results/closed_loop_seed0/$name:$name" --out "results/closed_loop_seed0/${name}_${metric}.png"
done
