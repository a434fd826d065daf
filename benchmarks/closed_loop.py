"""What the closed loop costs per action, and per episode, against the open loop.

    python benchmarks/closed_loop.py [--ns 3,8,14] [--scenes 2] [--seed 0] [--policy h-a]

For each N it plays ``--scenes`` of the evaluation protocol's held-out YCB scenes
(`shelf_env.evaluation.protocol.scene_seed`) greedily with ``--policy`` under three conditions, scene by
scene so that all three see the same machine load: the open loop (the env's default), the closed
loop with its defaults (``closed_loop=True``) and the closed loop with ``safe_picks=True`` (issue
13's recommended setting). It prints the wall time of ``env.step`` per action (the policy's own
choice is not timed), actions per episode, wall time per episode, and the ratios closed / open
measured in this run. Episodes differ once an intervention changes the scene, so the per-episode
figure mixes the cost of an action with how many actions the episode took; the per-action one is
the price of watching.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from shelf_env import params
from shelf_env.evaluation.protocol import make_env, make_policy, run_episode, scene_seed

CONDITIONS: dict[str, dict] = {
    "open": {},
    "closed": {"closed_loop": True},
    "closed+safe": {"closed_loop": True, "safe_picks": True},
}


class StepTimer(gym.Wrapper):
    """Adds up the wall time spent in ``env.step`` (the policy's own choice is not timed)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.seconds = 0.0

    def step(self, action):
        t = time.perf_counter()
        try:
            return self.env.step(action)
        finally:
            self.seconds += time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ns", default="3,8,14", help="comma-separated numbers of objects")
    parser.add_argument("--scenes", type=int, default=2, help="held-out scenes per N")
    parser.add_argument("--seed", type=int, default=0, help="evaluation seed of the scenes")
    parser.add_argument("--policy", default="h-a", help="h-a, h-d or a model zip")
    args = parser.parse_args()
    ns = [int(n) for n in args.ns.split(",")]
    if args.scenes < 1 or any(not 1 <= n <= params.MAX_OBJECTS for n in ns):
        parser.error(f"--scenes must be >= 1 and every N in 1..{params.MAX_OBJECTS}")

    print(f"policy {args.policy}, {args.scenes} scenes per N (seed {args.seed}), YCB objects")
    print(f"{'N':>3} {'condition':>12} {'ms/action':>10} {'actions/ep':>11} {'s/episode':>10} "
          f"{'x action':>9} {'x episode':>10}")
    for n in ns:
        envs = {name: StepTimer(make_env(args.policy, n, "ycb", conditions=cond))
                for name, cond in CONDITIONS.items()}
        policies = {name: make_policy(args.policy, env) for name, env in envs.items()}
        totals = {name: [0, 0.0] for name in CONDITIONS}
        for run in range(args.scenes):
            for name, env in envs.items():
                totals[name][0] += run_episode(env, policies[name], scene_seed(args.seed, n, run))["actions"]
        for name, env in envs.items():
            totals[name][1] = env.seconds
            env.close()
        base_action = totals["open"][1] / totals["open"][0]
        base_episode = totals["open"][1] / args.scenes
        for name, (actions, seconds) in totals.items():
            per_action, per_episode = seconds / actions, seconds / args.scenes
            print(f"{n:>3} {name:>12} {1000 * per_action:>10.0f} {actions / args.scenes:>11.1f} "
                  f"{per_episode:>10.1f} {per_action / base_action:>9.2f} {per_episode / base_episode:>10.2f}")


if __name__ == "__main__":
    main()
