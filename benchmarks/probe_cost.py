"""What a forked probe costs with and without the next observation, on the teacher dataset's kind of states.

    python benchmarks/probe_cost.py [--ns 5 8 11] [--scenes 3] [--actions 6]

For each N it plays ``--scenes`` training-object scenes of the dataset's kind (seeds outside the evaluation's)
with H-d for two steps, and at each visited state probes ``--actions`` random allowed actions twice: with
`shelf_env.privileged.lookahead.probe_step` (the copy steps and renders the next observation) and with
`probe_outcome` (the copy steps without the camera). It prints the seconds per probe of each, their ratio, and
whether the two reported the same outcome for every action (they must: the camera runs after the physics).
One process, one thread; the probes alternate so that a busy machine slows both alike.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from shelf_env.baselines.heuristics import DistanceHeuristic  # noqa: E402
from shelf_env.privileged.lookahead import probe_outcome, probe_step  # noqa: E402

SEED = 77_000  # scenes of this benchmark only


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--ns", type=int, nargs="+", default=[5, 8, 11], help="numbers of objects")
    p.add_argument("--scenes", type=int, default=3, help="scenes per N")
    p.add_argument("--actions", type=int, default=6, help="random allowed actions probed per state")
    args = p.parse_args()
    torch.set_num_threads(1)
    rng = np.random.default_rng(0)
    print(f"{args.scenes} scenes per N, 2 states each, {args.actions} actions per state, one thread")
    print("| N | probes | probe_step s | probe_outcome s | ratio | same outcomes |")
    print("|---|---|---|---|---|---|")
    for n in args.ns:
        env = gym.make("ShelfSort-v0", num_objects=n, object_set="train", pixel_size=0.01)
        full = blind = 0.0
        same = probes = 0
        for scene in range(args.scenes):
            obs, _ = env.reset(seed=SEED + 100 * n + scene)
            for _ in range(2):
                allowed = np.flatnonzero(env.unwrapped.action_masks())
                for action in rng.choice(allowed, size=min(args.actions, len(allowed)), replace=False):
                    start = time.perf_counter()
                    a = probe_step(env, int(action))
                    middle = time.perf_counter()
                    b = probe_outcome(env, int(action))
                    full += middle - start
                    blind += time.perf_counter() - middle
                    probes += 1
                    same += (a.reward, a.terminated, a.fell, a.is_success, a.num_sorted) == (
                        b.reward, b.terminated, b.fell, b.is_success, b.num_sorted)
                obs, _, terminated, truncated, _ = env.step(int(DistanceHeuristic(env).predict(obs)[0]))
                if terminated or truncated:
                    break
        env.close()
        print(f"| {n} | {probes} | {full / probes:.3f} | {blind / probes:.3f} | {blind / full:.2f} | "
              f"{same}/{probes} |", flush=True)


if __name__ == "__main__":
    main()
