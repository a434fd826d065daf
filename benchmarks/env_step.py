"""Throughput of ShelfSort-v0 steps, and their overhead over the physics + rendering floor.

    python benchmarks/env_step.py [--steps 30] [--seed 0] [--profile]

For N = 1, 8, 14 objects it runs a fixed mix of picks and pushes on object pixels and prints
actions/s and, per step, the ratio of the step's wall time to its floor measured in the same
run: the time of the step's own physics steps (pybullet.stepSimulation calls) plus the time of
its one camera render. Everything else (IK, motor commands, heightmap, recolouring, reward,
checks) is the overhead; the target is a ratio <= 1.3.

``--profile`` splits the same actions into where their time goes, in ms per action: physics steps
during the motion, the motion's own computation (IK, motor commands, contact checks), physics
while the scene settles, the camera render, the heightmap (point cloud, cells, recolouring) and
the rest (task rules, masks, bookkeeping).

``--compare [OLD NEW]`` (default ``reference fast``, see `shelf_env.world.cabinet.PHYSICS`; a setting may
also be given as ITERATIONS:RESIDUAL:SKIP, e.g. 20:1e-5:1) times one action under two physics
settings in one run: for each of ``--scenes`` scenes per N, random actions on object pixels are
drawn and run under OLD, then the same action indices are replayed under NEW from the same scene,
scene by scene, so that both see the same machine load. It prints ms per action for both and the ratio old / new.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pybullet as pb

from shelf_env.env import ShelfSortEnv
from shelf_env.world.cabinet import Physics


class Timed:
    """Accumulates the wall time of calls to a function."""

    def __init__(self, fn):
        self.fn, self.total = fn, 0.0

    def __call__(self, *args, **kwargs):
        t = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.total += time.perf_counter() - t


def run(n: int, steps: int, seed: int) -> tuple[float, float, float]:
    env = ShelfSortEnv(num_objects=n, max_actions=10_000)
    client = env.client
    physics = Timed(lambda: pb.stepSimulation(physicsClientId=client))
    render = Timed(env.camera.render)
    env.camera.render = render

    def reset(**kwargs) -> None:
        env.reset(**kwargs)  # every reset builds a new robot (history-free episodes): time its steps
        robot = env.robot
        robot.step = lambda: (physics(), setattr(robot, "physics_steps", robot.physics_steps + 1))

    rng = np.random.default_rng(seed)
    reset(seed=seed)
    wall = floor = 0.0
    done = 0
    while done < steps:
        cells = np.argwhere(env._semantic[0] >= 0)
        if len(cells) == 0:
            reset()
            continue
        r, c = cells[rng.integers(len(cells))]
        action = env.codec.encode(env.map_names[int(rng.integers(len(env.map_names)))], int(r), int(c))
        physics.total = render.total = 0.0
        t = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        wall += time.perf_counter() - t
        floor += physics.total + render.total
        done += 1
        if terminated or truncated:
            reset()
    env.close()
    return steps / wall, wall / steps, wall / floor


PHASES = ("motion physics", "motion other", "settle physics", "render", "heightmap", "rest")


def profile(n: int, steps: int, seed: int) -> dict[str, float]:
    """Milliseconds per action in each of `PHASES` (same action mix as `run`)."""
    env = ShelfSortEnv(num_objects=n, max_actions=10_000)
    client, totals = env.client, dict.fromkeys(PHASES, 0.0)
    where = ["motion"]

    def physics() -> None:
        t = time.perf_counter()
        pb.stepSimulation(physicsClientId=client)
        totals[f"{where[0]} physics"] += time.perf_counter() - t

    def timed(fn, key: str | None, phase: str | None = None):
        def call(*args, **kwargs):
            previous = where[0]
            if phase is not None:
                where[0] = phase
            t = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                if key is not None:
                    totals[key] += time.perf_counter() - t
                where[0] = previous
        return call

    render = Timed(env.camera.render)
    env.camera.render = render
    semantic = Timed(env.camera.semantic_map)
    env.camera.semantic_map = semantic

    def reset(**kwargs) -> None:
        env.reset(**kwargs)
        robot = env.robot
        robot.step = lambda: (physics(), setattr(robot, "physics_steps", robot.physics_steps + 1))
        env.world.settle = timed(env.world.settle, None, phase="settle")

    rng = np.random.default_rng(seed)
    reset(seed=seed)
    wall, done = 0.0, 0
    while done < steps:
        cells = np.argwhere(env._semantic[0] >= 0)
        if len(cells) == 0:
            reset(seed=int(rng.integers(10**6)))
            continue
        r, c = cells[rng.integers(len(cells))]
        action = env.codec.encode(env.map_names[int(rng.integers(len(env.map_names)))], int(r), int(c))
        before = dict(totals)
        render.total = semantic.total = 0.0
        runner = env.primitive_runner
        spans = {name: timed(getattr(runner, name), "motion other") for name in ("push", "pick", "place")}
        for name, fn in spans.items():
            setattr(runner, name, fn)
        t = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        wall += time.perf_counter() - t
        for name in spans:
            delattr(runner, name)
        # "motion other" so far holds the whole primitive: take its physics out
        totals["motion other"] -= totals["motion physics"] - before["motion physics"]
        totals["render"] += render.total
        totals["heightmap"] += semantic.total - render.total
        done += 1
        if terminated or truncated:
            reset(seed=int(rng.integers(10**6)))
    env.close()
    totals["rest"] = wall - sum(totals[k] for k in PHASES if k != "rest")
    return {k: 1e3 * v / steps for k, v in totals.items()}


def compare(n: int, scenes: int, actions: int, seed: int, old: Physics, new: Physics) -> tuple[float, float, int]:
    """(ms per action under ``old``, under ``new``, actions timed): same scenes, same action indices."""
    envs = [ShelfSortEnv(num_objects=n, max_actions=10_000, physics=p) for p in (old, new)]
    rng = np.random.default_rng(seed)
    wall, count = [0.0, 0.0], [0, 0]
    for scene in range(scenes):
        scene_seed = seed * 1000 + scene
        played: list[int] = []
        for k, env in enumerate(envs):
            env.reset(seed=scene_seed)
            for i in range(actions):
                if k == 0:  # draw on OLD's observation; NEW replays the same indices
                    cells = np.argwhere(env._semantic[0] >= 0)
                    if len(cells) == 0:
                        break
                    r, c = cells[rng.integers(len(cells))]
                    played.append(env.codec.encode(env.map_names[int(rng.integers(len(env.map_names)))],
                                                   int(r), int(c)))
                elif i >= len(played):
                    break
                t = time.perf_counter()
                _, _, terminated, truncated, _ = env.step(played[i])
                wall[k] += time.perf_counter() - t
                count[k] += 1
                if terminated or truncated:
                    break
    for env in envs:
        env.close()
    return 1e3 * wall[0] / max(count[0], 1), 1e3 * wall[1] / max(count[1], 1), count[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", action="store_true", help="where an action's time goes, per phase")
    ap.add_argument("--compare", nargs="*", type=Physics.parse, metavar="PHYSICS",
                    help="old vs new physics (default: reference fast), ms per action and ratio")
    ap.add_argument("--scenes", type=int, default=6, help="scenes per N for --compare")
    ap.add_argument("--actions", type=int, default=8, help="actions per scene for --compare")
    args = ap.parse_args()
    if args.compare is not None:
        if len(args.compare) not in (0, 2):
            ap.error(f"--compare takes no setting or two (OLD NEW), got {len(args.compare)}")
        old, new = args.compare or [Physics.named("reference"), Physics.named("fast")]
        print(f"old: {old}\nnew: {new}")
        print(f"{'N':>3} {'old ms':>8} {'new ms':>8} {'old/new':>8} {'actions':>8}")
        for n in (1, 8, 14):
            ms_old, ms_new, count = compare(n, args.scenes, args.actions, args.seed, old, new)
            print(f"{n:>3} {ms_old:>8.0f} {ms_new:>8.0f} {ms_old / ms_new:>8.2f} {count:>8}", flush=True)
        return
    if args.profile:
        print(f"{'N':>3} " + " ".join(f"{k:>15}" for k in PHASES) + f" {'total':>8}   (ms per action)")
        for n in (1, 8, 14):
            ms = profile(n, args.steps, args.seed)
            print(f"{n:>3} " + " ".join(f"{ms[k]:>15.1f}" for k in PHASES) + f" {sum(ms.values()):>8.1f}")
        return
    print(f"{'N':>3} {'actions/s':>10} {'ms/step':>8} {'step/floor':>11}")
    for n in (1, 8, 14):
        rate, per_step, ratio = run(n, args.steps, args.seed)
        print(f"{n:>3} {rate:>10.2f} {per_step * 1e3:>8.0f} {ratio:>11.3f}")


if __name__ == "__main__":
    main()
