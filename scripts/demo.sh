#!/usr/bin/env bash
# Install everything needed (see setup.sh) and run the main job: shelf-demo with its defaults —
# the shipped P+S model (or, until it exists, the best committed checkpoint) sorts one unseen YCB
# scene; the GIF goes to docs/demo.gif. Extra arguments go to shelf-demo (--policy, --n, --seed,
# --object-set, --out).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
shelf-demo "$@"
