#!/usr/bin/env bash
# How many falls could a better choice of action avoid? (issue 10: "if the reason is the env, show it")
# H-d and H-a beside their privileged one-step lookahead versions (shelf_env.privileged.lookahead: each pick is
# first tried in an exact forked copy of the env, and picks that drop an object are vetoed when
# another visible object's pick, or a push, does not), the same scenes as issue 10 (seed 0 at N = 5, 8, 11,
# 30 runs; the H-d and H-a cells are copied from results/models). A lookahead episode that still
# ends with a fall met a state where every visible unsorted object's pick and every probed push
# drops something (or, every visible object looking sorted, every uncovering pick and push does);
# results/lookahead/invalid_steps.md counts which (on these scenes: none, at every N).
# Resumable; extra arguments go to shelf-evaluate (e.g. --ns 3-14 --seeds 3 for issue 10's grid).
set -euo pipefail
cd "$(dirname "$0")/../.."
bash scripts/setup.sh >/dev/null
. .venv/bin/activate
shelf-evaluate --policies h-d h-a h-d-lookahead h-a-lookahead --ns 5,8,11 --runs 30 --seeds 1 \
    --object-sets ycb --out results/lookahead --reuse-cells results/models "$@"
python -m shelf_env.evaluation.report results/lookahead --learned h-a-lookahead --pick-only h-d-lookahead
# at which kind of step the lookahead's invalid episodes ended (results/lookahead/invalid_steps.md)
python -m research.lookahead_falls results/lookahead
# (none of its episodes fell: to see what a plain heuristic's falls dropped, run
#  python -m shelf_env.evaluation.traces results/lookahead --policies h-d h-a --ns 8 --limit 6)
