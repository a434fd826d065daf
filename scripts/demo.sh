#!/usr/bin/env bash
# Install everything needed (see setup.sh) and run the main job: roll out a scripted policy in
# ShelfSort-v0 and write a picture of the scene next to its heightmap (docs/scene_and_heightmap.png).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
python examples/demo.py "$@"
