"""Thin alias of ``shelf-train`` (`shelf_env.cli.train`), kept for the commands in the docs:

    python examples/train.py --out runs/curriculum --hours 2 [--preset recipe] [--set KEY=VALUE ...]
"""

from shelf_env.cli.train import *  # noqa: F403  (main, BudgetAndCheckpoint, ... for scripts that import train)
from shelf_env.cli.train import main

if __name__ == "__main__":
    raise SystemExit(main())
