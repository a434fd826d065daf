#!/usr/bin/env bash
# Install what the demo needs (scripts/setup.sh demo) and run the main job: shelf-demo with its
# defaults — the shipped P+S model sorts one unseen YCB scene, greedily within the env's masks; the
# GIF goes to runs/demo.gif. Extra arguments go to shelf-demo (--policy, --n, --seed, --object-set,
# --out); the README's GIF is `bash scripts/demo.sh --out docs/demo.gif`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh demo
. .venv/bin/activate
shelf-demo "$@"
