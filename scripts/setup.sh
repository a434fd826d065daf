#!/usr/bin/env bash
# Create .venv (if missing) and install the project into it.
#   bash scripts/setup.sh        everything: the project with its test, extra, zoo and ray dependencies
#   bash scripts/setup.sh demo   only what shelf-demo needs: the project and its runtime dependencies
# CPU torch 2.13.0 goes first: any other torch request may pull gigabytes of CUDA packages.
set -euo pipefail
cd "$(dirname "$0")/.."
what=${1:-all}
case $what in
all) target=".[test,extra,zoo,ray]" ;;
demo) target="." ;;
*) echo "usage: bash scripts/setup.sh [all|demo] (got $what)" >&2; exit 2 ;;
esac
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
. .venv/bin/activate
pip install --quiet torch==2.13.0
pip install --quiet -e "$target"
