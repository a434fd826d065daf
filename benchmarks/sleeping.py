"""ShelfSort-v0 with and without Bullet sleeping: cost per action and per physics step, and outcomes.

    python benchmarks/sleeping.py [--n 8] [--episodes 4] [--object-set ycb]

Plays H-d (`shelf_env.baselines.heuristics.DistanceHeuristic`) from the same seeded scenes twice, once with
``sleeping=False`` (every object simulated at every physics step) and once with ``sleeping=True``
(the default: objects at rest sleep until touched), alternating the two modes episode by episode so
that both see the same machine load. Prints seconds per action (whole episodes, reset
included), milliseconds per physics step and the ratios off / on measured in this run, and each
episode's outcome in both modes (sleeping is meant to change speed, not results).
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import shelf_env  # noqa: F401
from shelf_env.baselines.heuristics import DistanceHeuristic
from shelf_env.evaluation.protocol import run_episode


def play(env: gym.Env, seed: int) -> tuple[float, int, int, tuple[bool, int, bool]]:
    """One H-d episode (the evaluation's own loop): (seconds, actions, physics steps, (success, actions, fell))."""
    start = time.perf_counter()
    out = run_episode(env, DistanceHeuristic(env), seed)
    seconds = time.perf_counter() - start
    # the reset built this episode's robot (history-free episodes): its counter holds the episode's steps
    steps = env.unwrapped.robot.physics_steps
    return seconds, out["actions"], steps, (out["success"], out["actions"], out["fell"])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=int, default=8)
    p.add_argument("--episodes", type=int, default=4)
    p.add_argument("--object-set", default="ycb")
    args = p.parse_args()
    envs = {mode: gym.make("ShelfSort-v0", num_objects=args.n, object_set=args.object_set, sleeping=mode)
            for mode in (False, True)}
    totals = {mode: [0.0, 0, 0] for mode in envs}
    for episode in range(args.episodes):
        outcomes = {}
        for mode, env in envs.items():
            seconds, actions, steps, outcome = play(env, 1000 + episode)
            totals[mode][0] += seconds
            totals[mode][1] += actions
            totals[mode][2] += steps
            outcomes[mode] = outcome
        print(f"episode {episode}: (success, actions, fell) off {outcomes[False]}  on {outcomes[True]}")
    per_action = {m: t[0] / t[1] for m, t in totals.items()}
    per_step = {m: 1e3 * t[0] / t[2] for m, t in totals.items()}
    print(f"N={args.n} {args.object_set}, {args.episodes} H-d episodes per mode")
    print(f"sleeping off: {per_action[False]:.3f} s/action, {per_step[False]:.3f} ms/physics step (incl. IK, camera)")
    print(f"sleeping on : {per_action[True]:.3f} s/action, {per_step[True]:.3f} ms/physics step (incl. IK, camera)")
    print(f"ratio off/on: {per_action[False] / per_action[True]:.2f} per action")
    for env in envs.values():
        env.close()


if __name__ == "__main__":
    main()
