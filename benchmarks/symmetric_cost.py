"""What averaging a P+S's Q-maps over the cabinet's 12 symmetries costs per decision, beside the plain model.

    python benchmarks/symmetric_cost.py [MODEL.zip] [--ns 5 8 11] [--decisions 20] [--threads 1]

For each N it takes the first observation of ``--decisions`` YCB scenes (evaluation seed 0's scenes) and
times the model's masked greedy ``predict`` and `research.symmetric_q.SymmetricQ`'s on the same observations
(each after one warm-up call), and prints both per decision, their ratio, and an env action's cost beside them
(one step from each first observation), so the share a decision adds to an episode shows, and in how many of those
states the averaged Q-maps choose another action than the plain model.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import gymnasium as gym
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.timing import first_states, seconds_per_action, seconds_per_call  # noqa: E402
from research.symmetric_q import SymmetricQ  # noqa: E402
from sb3_pixeldqn import PixelDoubleDQN  # noqa: E402
from shelf_env.policies import checkpoint_pixel_size  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("model", nargs="?", default="examples/pretrained/p_s.zip", help="a PixelDoubleDQN zip")
    p.add_argument("--ns", type=int, nargs="+", default=[5, 8, 11], help="numbers of objects")
    p.add_argument("--decisions", type=int, default=20, help="observations (scenes) per N")
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    model = PixelDoubleDQN.load(args.model, device="cpu")
    pixel = checkpoint_pixel_size(args.model)
    print(f"{args.model}: {args.decisions} decisions per N, {args.threads} torch thread(s)")
    for n in args.ns:
        env = gym.make("ShelfSort-v0", num_objects=n, object_set="ycb", pixel_size=pixel)
        try:
            states = first_states(env, n, args.decisions)
            sym = SymmetricQ.for_env(model, env)
            plain_s = seconds_per_call(lambda s: model.predict(s[0], deterministic=True, action_masks=s[1]), states)
            sym_s = seconds_per_call(lambda s, sym=sym: sym.predict(s[0], action_masks=s[1]), states)
            differ = sum(int(model.predict(o, deterministic=True, action_masks=m)[0])
                         != int(sym.predict(o, action_masks=m)[0]) for o, m in states)
            step_s = seconds_per_action(env, n, states,
                                        lambda o, m: model.predict(o, deterministic=True, action_masks=m)[0])
        finally:
            env.close()
        print(f"N = {n:2d}: plain {plain_s * 1e3:6.1f} ms, symmetric ({sym.n_views} views) {sym_s * 1e3:6.1f} ms per "
              f"decision, {sym_s / plain_s:4.1f}x; one env action {step_s * 1e3:6.0f} ms "
              f"(symmetric decision + action {(sym_s + step_s) / (plain_s + step_s):4.2f}x plain); "
              f"the two choose differently in {differ} of {len(states)} first states", flush=True)


if __name__ == "__main__":
    main()
