"""Thin alias of ``shelf-evaluate`` (`shelf_env.cli.evaluate`), kept for the commands in the docs:

    python examples/evaluate.py --policies h-d h-a random --ns 3-14 --runs 20 --seeds 2 --out results/baselines
"""

from shelf_env.cli.evaluate import main

if __name__ == "__main__":
    raise SystemExit(main())
