#!/usr/bin/env bash
# Create .venv (if missing) and install the project with its test, extra, zoo and ray dependencies.
# CPU torch 2.13.0 goes first: any other torch request may pull gigabytes of CUDA packages.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
. .venv/bin/activate
pip install --quiet torch==2.13.0
pip install --quiet -e ".[test,extra,zoo,ray]"
