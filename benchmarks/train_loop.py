"""Env steps per hour of the training loop: the recipe vs issue 3's loop, measured in one run.

    python benchmarks/train_loop.py [--steps 150] [--rounds 2] [--threads 2] [--n 3]

Each configuration (`shelf_env.training.config.PRESETS`: ``recipe`` and ``issue3``) trains at N objects
for ``--steps`` env steps after its ``learning_starts``, in ``--rounds`` interleaved rounds (so
that a change in the machine's load hits both), and the script prints seconds per env step,
env steps per hour and the ratio recipe / issue 3. Demonstration collection is timed separately
(it happens once per run). Everything else a step costs is in: the env action, masks, the
gradient step with its margin loss and augmentation, the buffer.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import torch as th
from stable_baselines3.common.logger import configure

import shelf_env  # noqa: F401
from shelf_env.training.config import PRESETS, demo_policy, make_env, make_model


def prepared_model(preset: str, n: int, seed: int) -> tuple[Any, Any, Any, float]:
    """(config, env, model, estimated seconds of the preset's demonstrations) for ``preset`` at N = n:
    a fresh model, logging off, with 40 demonstration steps stored when the preset has them (so that
    batches sample demonstrations, as in training)."""
    config = PRESETS[preset].replace(start_objects=n, max_objects=n)
    env = make_env(config)
    model = make_model(config, env, seed=seed)
    model.set_logger(configure(None, []))
    demo_seconds = 0.0
    demos = demo_policy(config, env)
    if demos is not None:
        t0 = time.perf_counter()
        model.collect_demonstrations(demos, 40)
        demo_seconds = (time.perf_counter() - t0) / 40 * config.demo_steps
    return config, env, model, demo_seconds


def timed_steps(preset: str, n: int, steps: int, seed: int) -> tuple[float, float]:
    """(seconds per env step while learning, seconds of demonstration collection) for one preset."""
    config, env, model, demo_seconds = prepared_model(preset, n, seed)
    model.learn(config.learning_starts)  # fill the buffer first; only learning steps are timed
    t0 = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    seconds = (time.perf_counter() - t0) / steps
    env.close()
    return seconds, demo_seconds


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=150)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--n", type=int, default=3)
    args = p.parse_args()
    th.set_num_threads(args.threads)
    results: dict[str, list[float]] = {"recipe": [], "issue3": []}
    demo = 0.0
    for r in range(args.rounds):
        for preset in results:
            seconds, demo_seconds = timed_steps(preset, args.n, args.steps, seed=r)
            results[preset].append(seconds)
            demo = max(demo, demo_seconds)
            print(f"round {r} {preset:7s}: {seconds:.3f} s/step", flush=True)
    mean = {k: sum(v) / len(v) for k, v in results.items()}
    for k, v in mean.items():
        print(f"{k:7s}: {v:.3f} s/env step = {3600 / v:,.0f} env steps/hour (N = {args.n}, {args.threads} threads)")
    print(f"recipe / issue3 env steps per hour: {mean['issue3'] / mean['recipe']:.2f}x")
    print(f"recipe demonstrations: {demo:.0f} s once per run (estimated from 40 steps)")


if __name__ == "__main__":
    main()
