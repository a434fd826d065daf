"""Issue 9, lever 9: does acting in an actor process pay on two cores? Measured in one run.

    python benchmarks/overlap.py [--ns 3 8] [--steps 100] [--threads 2]

For each N, the recipe's training loop (`shelf_env.training.config.PRESETS["recipe"]`, what `shelf-train`
runs) two ways on the same two cores, one after the other, each timed over ``--steps`` env steps
after its ``learning_starts``:

- **sequential** (``actor=false``): one process, torch on ``--threads`` threads, act then learn,
  one gradient step per env step (as `benchmarks/train_loop.py` times it);
- **actor** (``actor=true``, `shelf-train --actor`): the env stepped by an actor process
  (`sb3_pixeldqn.actor.ActorVecEnv`: env + a CPU copy of the Q-network, 1 torch thread, the model's
  ε-greedy masked policy, weights refreshed every ``actor_sync_every`` updates) while
  `PixelDoubleDQN.learn` consumes its transitions with ``--threads`` − 1 threads, at the same replay
  ratio (one gradient step per transition; the actor waits when ``actor_max_lag`` ahead).

Prints env steps per hour of each and the ratio. The issue adopts the actor only if the ratio is
at least 1.3 (docs/experiments/learning-recipe.md, lever 9).
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import torch as th

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from shelf_env.training.config import make_actor_env

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from train_loop import prepared_model, timed_steps  # noqa: E402  (shared with the sequential measurement)


def actor_seconds(n: int, steps: int, seed: int, threads: int) -> float:
    """Seconds per env step of the recipe's loop at N = n with its env in an actor process."""
    th.set_num_threads(max(1, threads - 1))
    config, env, model, _ = prepared_model("recipe", n, seed)
    actor_env = make_actor_env(config.replace(actor=True))
    model.set_env(actor_env)
    env.close()
    try:
        model.learn(config.learning_starts)  # fill the buffer first; only learning steps are timed
        t0 = time.perf_counter()
        model.learn(steps, reset_num_timesteps=False)
        return (time.perf_counter() - t0) / steps
    finally:
        actor_env.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ns", type=int, nargs="+", default=[3, 8])
    p.add_argument("--steps", type=int, default=100, help="env steps timed per N and way")
    p.add_argument("--threads", type=int, default=2, help="torch threads in all (the two cores)")
    args = p.parse_args()
    for n in args.ns:
        th.set_num_threads(args.threads)
        seq, _ = timed_steps("recipe", n, args.steps, seed=0)
        print(f"N = {n:2d} sequential ({args.threads} threads): {seq:.3f} s/env step = "
              f"{3600 / seq:,.0f} env steps/hour", flush=True)
        act = actor_seconds(n, args.steps, seed=0, threads=args.threads)
        print(f"N = {n:2d} actor process (1 thread) + learner ({max(1, args.threads - 1)} thread): {act:.3f} s/env step"
              f" = {3600 / act:,.0f} env steps/hour", flush=True)
        print(f"N = {n:2d} actor / sequential env steps per hour: {seq / act:.2f}x", flush=True)


if __name__ == "__main__":
    main()
