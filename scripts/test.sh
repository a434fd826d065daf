#!/usr/bin/env bash
# Install everything needed (see setup.sh), lint, type-check, and run the default test suite.
# Extra arguments go to pytest, e.g. `bash scripts/test.sh -m slow` for the long tests.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
ruff check .
mypy  # sb3_pixeldqn and shelf_env, configured in pyproject.toml
python -m pytest -q "$@"
