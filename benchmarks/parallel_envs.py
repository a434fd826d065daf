"""Issue 10: env steps per hour of the training loop with parallel envs, on this machine, in one run.

    python benchmarks/parallel_envs.py [--ns 3 8] [--n-envs 1 15] [--seconds 60] [--device auto]

For each N and each number of envs K, the ``p_s`` preset's training loop (what
``shelf-train --preset p_s --n-envs K`` runs: the learning recipe, P+S) at N objects: K env
processes (`shelf_env.training.config.make_parallel_env`; K = 1 is the ordinary in-process env), the
learner on ``--device`` (SB3's; ``auto`` takes the GPU when there is one), K gradient steps after
each collection step of the K envs, so that every K trains one gradient step per env step. After
the buffer's warm-up (``learning_starts`` steps), the loop runs for ``--seconds`` and the script
prints env steps and gradient steps per hour and the ratio of env steps per hour to K = 1's at the
same N. The machine (CPUs, device) is printed first: compare ratios within one run, and absolute
numbers only between runs on the same machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import configure

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from shelf_env.training.config import PRESETS, demo_policy, make_env, make_model, use_parallel_envs


class StopAfter(BaseCallback):
    """Stops learning once ``seconds`` have passed since training started."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.start = 0.0

    def _on_training_start(self) -> None:
        self.start = time.perf_counter()

    def _on_step(self) -> bool:
        return time.perf_counter() - self.start < self.seconds


def measure(n: int, n_envs: int, seconds: float, device: str, seed: int = 0) -> tuple[float, float]:
    """(env steps per hour, gradient steps per hour) of the ``p_s`` loop at N = n with ``n_envs`` envs."""
    config = PRESETS["p_s"].replace(start_objects=n, max_objects=n, n_envs=n_envs)
    env = make_env(config)
    model = make_model(config, env, seed=seed, device=device)
    model.set_logger(configure(None, []))
    demos = demo_policy(config, env)
    if demos is not None:  # demonstrations in the batches, as in training (not timed)
        model.collect_demonstrations(demos, 40)
    use_parallel_envs(model, config, seed=seed)  # what shelf-train --n-envs does
    try:
        model.learn(config.learning_starts + n_envs)  # the warm-up; only learning steps are timed
        steps, updates = model.num_timesteps, model._n_updates
        t0 = time.perf_counter()
        model.learn(10**9, callback=StopAfter(seconds), reset_num_timesteps=False)
        elapsed = time.perf_counter() - t0
        return ((model.num_timesteps - steps) * 3600 / elapsed, (model._n_updates - updates) * 3600 / elapsed)
    finally:
        model.get_env().close()  # type: ignore[union-attr]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ns", type=int, nargs="+", default=[3, 8])
    p.add_argument("--n-envs", type=int, nargs="+", default=[1, 2])
    p.add_argument("--seconds", type=float, default=60.0, help="timed seconds per (N, K)")
    p.add_argument("--device", default="auto")
    p.add_argument("--threads", type=int, default=2, help="torch threads of the learner")
    args = p.parse_args()
    if any(k < 1 for k in args.n_envs) or args.seconds <= 0:
        p.error("--n-envs must be >= 1 and --seconds > 0")
    th.set_num_threads(args.threads)
    gpu = f", {th.cuda.get_device_name(0)}" if th.cuda.is_available() else ""
    print(f"machine: {platform.system()} {platform.machine()}, {os.cpu_count()} CPUs{gpu}; device {args.device}, "
          f"{args.threads} learner threads, torch {th.__version__}", flush=True)
    for n in args.ns:
        base = None
        for k in args.n_envs:
            env_rate, grad_rate = measure(n, k, args.seconds, args.device)
            base = base or (env_rate if k == 1 else None)
            ratio = f", {env_rate / base:.2f}x K = 1" if base else ""
            print(f"N = {n:2d}, K = {k:2d} envs: {env_rate:9,.0f} env steps/hour, {grad_rate:9,.0f} gradient "
                  f"steps/hour{ratio}", flush=True)


if __name__ == "__main__":
    main()
