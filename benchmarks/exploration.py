"""Uniform vs masked exploration: how many exploratory actions do anything, and what it does to learning.

    python benchmarks/exploration.py [--actions 30] [--ns 1 3 8] [--learn-steps 400]

Part 1 (ShelfSort-v0, P+S): from fresh scenes, take ``--actions`` purely exploratory actions per
N, either uniform over all 3 x 80 x 120 actions or drawn as PixelDoubleDQN draws them with
the env's ``action_masks()`` (a map uniformly, then a pixel the env marks useful). An
action is *effective* if some object moved more than 5 mm. Prints the effective fraction per mode
and the ratio masked / uniform, measured in this run.

Part 2 (the synthetic FindTheSquare env of tests/, 4 x 12 x 20, one map): trains PixelDoubleDQN for
``--learn-steps`` steps with each mode and prints the greedy hit rate on 50 fresh images.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import gymnasium as gym
import numpy as np
import torch as th

import shelf_env  # noqa: F401
from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.pixel_dqn import draw_masked_action

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from pixel_envs import FindTheSquareEnv  # noqa: E402

MOVED = 0.005


def effective_fraction(n: int, mode: str, actions: int, seed: int) -> float:
    env = gym.make("ShelfSort-v0", num_objects=n).unwrapped
    rng = np.random.default_rng(seed)
    effective, taken, episode = 0, 0, 0
    env.reset(seed=seed)
    while taken < actions:
        before = env.world.positions()[:, :3].copy()
        if mode == "uniform":
            action = int(rng.integers(env.action_space.n))
        else:
            action = draw_masked_action(env.action_masks(), len(env.map_names), rng)
        _, _, terminated, truncated, _ = env.step(action)
        taken += 1
        after = env.world.positions()[:, :3]
        moved = len(after) != len(before) or np.linalg.norm(after - before, axis=1).max() > MOVED
        effective += int(moved)
        if terminated or truncated:
            episode += 1
            env.reset(seed=seed + 1000 * episode)
    env.close()
    return effective / actions


def learned_hit_rate(mask: bool, steps: int) -> float:
    model = PixelDoubleDQN("FCNPolicy", FindTheSquareEnv(), policy_kwargs=dict(maps=[("pick", 0)]), seed=0,
                           learning_rate=1e-3, learning_starts=50, exploration_timesteps=steps // 2,
                           buffer_size=2000, masked=False, masked_exploration=mask)
    model.learn(steps)
    env, hits = FindTheSquareEnv(), 0
    for s in range(50):
        obs, _ = env.reset(seed=10_000 + s)
        hits += env.on_square(int(model.predict(obs, deterministic=True)[0]))
    return hits / 50


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--actions", type=int, default=30)
    parser.add_argument("--ns", type=int, nargs="+", default=[1, 3, 8])
    parser.add_argument("--learn-steps", type=int, default=400)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    print(f"Part 1: fraction of exploratory actions that move an object (ShelfSort-v0, {args.actions} per cell)")
    for n in args.ns:
        uniform = effective_fraction(n, "uniform", args.actions, seed=n)
        masked = effective_fraction(n, "masked", args.actions, seed=n)
        ratio = masked / uniform if uniform else float("inf")
        print(f"  N={n:2d}  uniform {uniform:5.1%}  masked {masked:5.1%}  masked/uniform {ratio:.1f}")
    print(f"Part 2: greedy hit rate after {args.learn_steps} steps on FindTheSquare (random pixel: ~4 %)")
    uniform, masked = learned_hit_rate(False, args.learn_steps), learned_hit_rate(True, args.learn_steps)
    print(f"  uniform {uniform:.0%}  masked {masked:.0%}")


if __name__ == "__main__":
    main()
