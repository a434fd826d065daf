"""What acting on the mean Q-maps of K models (`sb3_pixeldqn.QEnsemble`) costs per decision, beside one model.

    python benchmarks/ensemble_cost.py [MODEL.zip ...] [--ns 5 8 11] [--decisions 20] [--threads 1]

The members default to the three shipped P+S checkpoints (the distilled model, v2 and v1: the same network, so
the cost is what matters here, not their agreement). For each N it takes the first observation of ``--decisions``
YCB scenes (evaluation seed 0's) and times the first member's masked greedy ``predict`` and the ensemble's on the
same observations (each after one warm-up call). It prints both per decision and their ratio, and one env action's
cost from those states, so that the share the ensemble adds to an episode shows.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import shelf_env  # noqa: E402, F401  (registers ShelfSort-v0)
from benchmarks.timing import first_states, seconds_per_action, seconds_per_call  # noqa: E402
from sb3_pixeldqn import PixelDoubleDQN, QEnsemble  # noqa: E402
from shelf_env.policies import checkpoint_pixel_size  # noqa: E402

SHIPPED = ["examples/pretrained/p_s.zip", "examples/pretrained/v2/p_s.zip", "examples/pretrained/v1/p_s.zip"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("models", nargs="*", default=SHIPPED, help="two or more PixelDoubleDQN zips of one layout")
    p.add_argument("--ns", type=int, nargs="+", default=[5, 8, 11], help="numbers of objects")
    p.add_argument("--decisions", type=int, default=20, help="observations (scenes) per N")
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    args = p.parse_args()
    if len(args.models) < 2:
        p.error("an ensemble needs two or more models")
    torch.set_num_threads(args.threads)
    models = [PixelDoubleDQN.load(m, device="cpu") for m in args.models]
    ensemble = QEnsemble(models)
    print(f"{len(models)} members ({', '.join(args.models)}): {args.decisions} decisions per N, "
          f"{args.threads} torch thread(s)")
    pixel = checkpoint_pixel_size(args.models[0])
    for n in args.ns:
        env = gym.make("ShelfSort-v0", num_objects=n, object_set="ycb", pixel_size=pixel)
        try:
            states = first_states(env, n, args.decisions)
            one = seconds_per_call(lambda s: models[0].predict(s[0], deterministic=True, action_masks=s[1]), states)
            mean = seconds_per_call(lambda s: ensemble.predict(s[0], action_masks=s[1]), states)
            step = seconds_per_action(env, n, states, lambda o, m: ensemble.predict(o, action_masks=m)[0])
        finally:
            env.close()
        print(f"N = {n:2d}: one model {one * 1e3:6.1f} ms, ensemble of {len(models)} {mean * 1e3:6.1f} ms per "
              f"decision, {mean / one:4.1f}x; one env action {step * 1e3:6.0f} ms "
              f"(ensemble decision + action {(mean + step) / (one + step):4.2f}x one model's)", flush=True)


if __name__ == "__main__":
    main()
