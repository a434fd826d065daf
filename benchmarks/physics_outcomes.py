"""Do two physics settings give the same outcomes? The heuristics on a fixed scene set, against Bullet's chaos.

    python benchmarks/physics_outcomes.py [--new fast] [--ns 3 8 14] [--runs 10] [--seed 7]
                                          [--policies h-d h-a] [--out results/physics/outcomes.json]

A cheaper action (`shelf_env.world.cabinet.Physics`) must leave what happens unchanged, but Bullet is
chaotic: any change at all, even a harmless one, sends a cluttered episode down another path. So
the comparison has a yardstick. Every (policy, N, run) scene of the evaluation protocol
(`shelf_env.evaluation.protocol.scene_seed`, YCB objects) is played three times:

- ``reference``: ``physics="reference"``, the physics every earlier result used;
- ``chaos``: the same, with every object spawned 0.1 mm deeper into the cabinet, a change that
  means nothing physically and only shows how far chaos alone moves the outcomes;
- ``new``: ``physics=--new``.

It prints, per N and over all N, for each setting: the success rate, the share of episodes with a
fall and the mean number of actions; and against ``reference``: the share of episodes with the
same outcome (success, fall) and the mean |difference| in actions. ``new`` agrees with the
reference as well as ``chaos`` does when its physics is the same up to chaos.
"""

from __future__ import annotations

import argparse
import contextlib
import pathlib
from collections.abc import Iterator

import gymnasium as gym
import numpy as np

import shelf_env  # noqa: F401
from shelf_env.evaluation.protocol import make_policy, run_episode, scene_seed
from shelf_env.files import write_json_atomically
from shelf_env.world import cabinet as world
from shelf_env.world.cabinet import Physics

SHIFT = 1e-4  # m, the chaos yardstick's nudge


@contextlib.contextmanager
def nudged() -> Iterator[None]:
    """Every object spawned SHIFT further into the cabinet (x) while inside the block."""
    original = world.World.add_object

    def add_object(self, spec, cls, x, y, yaw):
        return original(self, spec, cls, x + SHIFT, y, yaw)

    world.World.add_object = add_object  # type: ignore[method-assign]
    try:
        yield
    finally:
        world.World.add_object = original  # type: ignore[method-assign]


def play(policy: str, n: int, runs: int, seed: int, physics: Physics, nudge: bool) -> list[tuple[bool, bool, int]]:
    """(success, fell, actions) of each run."""
    env = gym.make("ShelfSort-v0", num_objects=n, object_set="ycb", physics=physics)
    agent = make_policy(policy, env)
    out = []
    with nudged() if nudge else contextlib.nullcontext():
        for run in range(runs):
            r = run_episode(env, agent, scene_seed(seed, n, run))
            out.append((bool(r["success"]), bool(r["fell"]), int(r["actions"])))
    env.close()
    return out


def stats(rows: list[tuple[bool, bool, int]], ref: list[tuple[bool, bool, int]]) -> dict[str, float]:
    a = np.array(rows, dtype=float)
    b = np.array(ref, dtype=float)
    return {"success": a[:, 0].mean(), "fell": a[:, 1].mean(), "actions": a[:, 2].mean(),
            "same_outcome": (a[:, :2] == b[:, :2]).all(1).mean(), "abs_d_actions": np.abs(a[:, 2] - b[:, 2]).mean()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--new", type=Physics.parse, default=Physics.named("fast"),
                    help="physics to compare with the reference: a name or ITERATIONS:RESIDUAL:SKIP")
    ap.add_argument("--ns", type=int, nargs="+", default=[3, 8, 14])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--policies", nargs="+", default=["h-d", "h-a"], choices=["h-d", "h-a"])
    ap.add_argument("--out", type=pathlib.Path, help="also write every episode and the table as JSON")
    args = ap.parse_args()
    reference = Physics.named("reference")
    settings = {"reference": (reference, False), "chaos": (reference, True), "new": (args.new, False)}
    print(f"new: {args.new}")
    episodes: dict[str, dict[int, list]] = {k: {} for k in settings}
    for n in args.ns:
        for name, (physics, nudge) in settings.items():
            episodes[name][n] = [e for policy in args.policies
                                 for e in play(policy, n, args.runs, args.seed, physics, nudge)]
    table = []
    print(f"{'N':>4} {'setting':>9} {'success':>8} {'fell':>6} {'actions':>8} {'same outcome':>13} "
          f"{'|d actions|':>12}")
    for n in [*args.ns, "all"]:
        for name in settings:
            rows = sum(episodes[name].values(), []) if n == "all" else episodes[name][n]
            ref = sum(episodes["reference"].values(), []) if n == "all" else episodes["reference"][n]
            s = stats(rows, ref)
            table.append({"n": n, "setting": name, **s})
            print(f"{n!s:>4} {name:>9} {s['success']:>8.2f} {s['fell']:>6.2f} {s['actions']:>8.2f} "
                  f"{s['same_outcome']:>13.2f} {s['abs_d_actions']:>12.2f}", flush=True)
    if args.out:
        played = {k: {str(n): v for n, v in d.items()} for k, d in episodes.items()}
        write_json_atomically(args.out, {"new": vars(args.new), "ns": args.ns, "runs": args.runs, "seed": args.seed,
                                         "policies": args.policies, "table": table, "episodes": played})


if __name__ == "__main__":
    main()
