"""What the geometry pick filter (`shelf_env.fall_filter`), the pick guard (`shelf_env.pick_guard`) and the loop breaker
add to a decision of the shipped P+S.

    python benchmarks/filter_cost.py [MODEL.zip] [--ns 5 8 11] [--decisions 20] [--threads 1]

The model defaults to the shipped ``examples/pretrained/p_s.zip``, played as its card says: under the
`GeometryRisk` beside it (``p_s.geometry_risk.pt``), the `PickGuard` and `sb3_pixeldqn.LoopBreaker`. For each N it
takes the first observation of ``--decisions`` YCB scenes (evaluation seed 0's) and times the bare model's masked
greedy ``predict`` and the wrapped policy's on the same observations (each after one warm-up call). It prints both per
decision, their ratio, and one env action's cost from those states, so that the share the wrappers add to an episode
shows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import shelf_env  # noqa: E402, F401  (registers ShelfSort-v0)
from benchmarks.timing import first_states, seconds_per_action, seconds_per_call  # noqa: E402
from shelf_env.pick_guard import PICK_GUARD  # noqa: E402
from shelf_env.policies import LOOP_BREAKER, checkpoint_pixel_size, make_policy  # noqa: E402

SHIPPED = "examples/pretrained/p_s.zip"


def measure(model: str, filtered: str, n: int, decisions: int) -> tuple[float, float, float]:
    """Seconds per decision of ``model`` and ``filtered``, and per env action, from the first states of N-object
    scenes."""
    env = gym.make("ShelfSort-v0", num_objects=n, object_set="ycb", pixel_size=checkpoint_pixel_size(model))
    try:
        bare, wrapped = make_policy(model, env), make_policy(filtered, env)
        start = np.array([True])  # each observation as an episode's first: the breaker bans nothing yet
        states = first_states(env, n, decisions)
        def filtered_action(o: np.ndarray, m: np.ndarray) -> np.ndarray:
            return wrapped.predict(o, deterministic=True, episode_start=start, action_masks=m)[0]

        one = seconds_per_call(lambda s: bare.predict(s[0], deterministic=True, action_masks=s[1]), states)
        both = seconds_per_call(lambda s: filtered_action(s[0], s[1]), states)
        step = seconds_per_action(env, n, states, filtered_action)
    finally:
        env.close()
    return one, both, step


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("model", nargs="?", default=SHIPPED, help="a P+S zip with a <stem>.geometry_risk.pt beside it")
    p.add_argument("--ns", type=int, nargs="+", default=[5, 8, 11], help="numbers of objects")
    p.add_argument("--decisions", type=int, default=20, help="observations (scenes) per N")
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    filtered = f"{args.model}+geometry-filter{PICK_GUARD}{LOOP_BREAKER}"
    print(f"{args.model} alone and as {filtered}: {args.decisions} decisions per N, {args.threads} torch thread(s)")
    for n in args.ns:
        one, both, step = measure(args.model, filtered, n, args.decisions)
        print(f"N = {n:2d}: the model {one * 1e3:6.1f} ms, with the wrappers {both * 1e3:6.1f} ms "
              f"per decision, {both / one:4.1f}x; one env action {step * 1e3:6.0f} ms (filtered decision + action "
              f"{(both + step) / (one + step):4.2f}x the model's)", flush=True)


if __name__ == "__main__":
    main()
