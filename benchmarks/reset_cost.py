"""What history-free episodes cost per reset: `ShelfSortEnv.reset` rebuilding the simulation (now)
vs only replacing the objects (before; history leaked between episodes), in one run.

    python benchmarks/reset_cost.py [--resets 30] [--object-set train]

For N = 1, 8 and 14 it alternates the two paths reset by reset (same seeds, same machine load) and
prints milliseconds per reset for each and the difference.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from shelf_env.env import ShelfSortEnv


def old_build_world(env: ShelfSortEnv) -> None:
    """The pre-fix path: keep the simulation, remove the previous objects (history survives)."""
    env._clear_scene()


def time_resets(n: int, resets: int, object_set: str) -> tuple[float, float]:
    new, old = ShelfSortEnv(num_objects=n, object_set=object_set), ShelfSortEnv(num_objects=n, object_set=object_set)
    old._build_world = lambda: old_build_world(old)  # type: ignore[method-assign]
    times: dict[str, list[float]] = {"new": [], "old": []}
    try:
        for i in range(resets):
            for name, env in (("new", new), ("old", old)) if i % 2 == 0 else (("old", old), ("new", new)):
                start = time.perf_counter()
                env.reset(seed=1000 + i)
                times[name].append(time.perf_counter() - start)
    finally:
        new.close()
        old.close()
    return float(np.median(times["new"])) * 1e3, float(np.median(times["old"])) * 1e3


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--resets", type=int, default=30)
    p.add_argument("--object-set", default="train", choices=["train", "ycb"])
    args = p.parse_args()
    print(f"{'N':>3} {'rebuild ms':>11} {'old ms':>8} {'cost ms':>8} {'ratio':>6}")
    for n in (1, 8, 14):
        new, old = time_resets(n, args.resets, args.object_set)
        print(f"{n:>3} {new:>11.1f} {old:>8.1f} {new - old:>8.1f} {new / old:>6.2f}")


if __name__ == "__main__":
    main()
