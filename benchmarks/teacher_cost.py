"""What a privileged teacher's decision costs: the one-step lookahead against the planning teacher, in one run.

    python benchmarks/teacher_cost.py [--ns 3 5 8] [--scenes 2] [--decisions 3] [--horizon 3] [--candidates 6]

For each N it plays the first ``--decisions`` decisions of ``--scenes`` YCB scenes (evaluation seed 0's
scenes, the same for both teachers; each decision's state comes from the lookahead's own play, so
both decide on identical states) and prints, per teacher, the wall-clock seconds and the env actions
(probes, rollout steps and the probes inside rollouts) per decision, and their ratio.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym

import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from shelf_env.evaluation.protocol import scene_seed
from shelf_env.privileged.lookahead import LookaheadDistance
from shelf_env.privileged.planning import PlanningTeacher


def measure(n: int, scenes: int, decisions: int, horizon: int, candidates: int) -> dict[str, tuple[float, float]]:
    env = gym.make("ShelfSort-v0", num_objects=n, object_set="ycb", pixel_size=0.01)
    seconds = {"lookahead": 0.0, "planner": 0.0}
    actions = {"lookahead": 0, "planner": 0}
    count = 0
    try:
        for run in range(scenes):
            obs, _ = env.reset(seed=scene_seed(0, n, run))
            for _ in range(decisions):
                lookahead, planner = LookaheadDistance(env), PlanningTeacher(env, horizon, candidates)
                start = time.perf_counter()
                planner.predict(obs)
                seconds["planner"] += time.perf_counter() - start
                start = time.perf_counter()
                action = int(lookahead.predict(obs)[0])
                seconds["lookahead"] += time.perf_counter() - start
                actions["planner"] += planner.stats["actions"]
                actions["lookahead"] += lookahead.stats["probes"]
                count += 1
                obs, _, terminated, truncated, _ = env.step(action)
                if terminated or truncated:
                    break
    finally:
        env.close()
    return {k: (seconds[k] / count, actions[k] / count) for k in seconds}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--ns", type=int, nargs="+", default=[3, 5, 8], help="numbers of objects")
    p.add_argument("--scenes", type=int, default=2, help="scenes per N")
    p.add_argument("--decisions", type=int, default=3, help="decisions per scene")
    p.add_argument("--horizon", type=int, default=3, help="the planner's rollout length (actions)")
    p.add_argument("--candidates", type=int, default=6, help="the planner's safe candidates rolled out")
    args = p.parse_args()
    print(f"planner: horizon {args.horizon}, {args.candidates} candidates; {args.scenes} scenes x {args.decisions} "
          "decisions per N")
    for n in args.ns:
        r = measure(n, args.scenes, args.decisions, args.horizon, args.candidates)
        (ls, la), (ps, pa) = r["lookahead"], r["planner"]
        print(f"N = {n:2d}: lookahead {ls:6.2f} s, {la:5.1f} env actions per decision; planner {ps:6.2f} s, "
              f"{pa:5.1f} env actions; planner / lookahead {ps / ls:5.1f}x time, {pa / max(la, 1e-9):5.1f}x actions",
              flush=True)


if __name__ == "__main__":
    main()
