"""What a labelled state of the teacher dataset costs when the teacher's pick probes render the copy's camera and
when they do not (`shelf_env.privileged.dataset.collect_episode`'s ``teacher_observes``).

    python benchmarks/collect_cost.py [--ns 5 8 11] [--scenes 1] [--model data/drivers/...zip]

For each N it collects ``--scenes`` training-object scenes of the dataset's kind (seeds of a series no collection
uses) twice, as a collection does (the driving model's greedy action executed where its probe stays valid,
``explore`` 1, up to 24 labels a state): once with a teacher that renders its pick probes (`probe_step`, every
collection before the option) and once with one that only steps them (`probe_outcome`). It prints the seconds per
labelled state of each, their ratio, and whether both collected the same episode (states, decisions and labels:
they must, since a pick's probe is read for its outcome alone). One process, one thread; the two alternate scene by
scene so that a busy machine slows both alike.
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

from shelf_env.actions import PRIMITIVES  # noqa: E402
from shelf_env.policies import make_policy  # noqa: E402
from shelf_env.privileged import dataset  # noqa: E402

SERIES = 90  # scene seeds of this benchmark only (`dataset.scene_seed`): no collection runs series 90
DRIVER = "data/drivers/p_s_dagger201_aug_mpa_r2_ce1_avg4.zip"  # series 3's driver


def same_episode(a: dataset.Episode, b: dataset.Episode) -> bool:
    """Bit for bit the same states, decisions and labels."""
    return (a.actions == b.actions and len(a.obs) == len(b.obs)
            and all(np.array_equal(x, y) for x, y in zip(a.obs, b.obs)) and a.states == b.states
            and a.labels == b.labels)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--ns", type=int, nargs="+", default=[5, 8, 11], help="numbers of objects")
    p.add_argument("--scenes", type=int, default=1, help="scenes per N")
    p.add_argument("--model", default=DRIVER, help="the driving model (a checkpoint, with wrappers if named)")
    args = p.parse_args()
    torch.set_num_threads(1)
    env = gym.make("ShelfSort-v0", num_objects=max(args.ns), object_set="train", primitives=PRIMITIVES,
                   pixel_size=dataset.PIXEL_SIZE)
    model = make_policy(args.model, env)
    print(f"{args.scenes} scenes per N, explore 1, up to 24 labels a state, one thread; driver {args.model}")
    print("| N | states | labels | teacher renders picks s/state | skips their camera s/state | ratio | same episode |")
    print("|---|---|---|---|---|---|---|")
    total = {True: 0.0, False: 0.0}
    states_all = 0
    for n in args.ns:
        env.unwrapped.set_num_objects(n)  # type: ignore[attr-defined]
        seconds = {True: 0.0, False: 0.0}
        states = labels = same = 0
        for scene in range(args.scenes):
            seed = dataset.scene_seed(SERIES, n, scene)
            episodes = {}
            for observes in (True, False):
                start = time.perf_counter()
                episodes[observes] = dataset.collect_episode(env, model, seed, np.random.default_rng(seed), 1.0,
                                                             teacher_observes=observes)
                seconds[observes] += time.perf_counter() - start
            states += len(episodes[False].obs)
            labels += len(episodes[False].labels["label_action"])
            same += same_episode(episodes[True], episodes[False])
        for k in total:
            total[k] += seconds[k]
        states_all += states
        print(f"| {n} | {states} | {labels} | {seconds[True] / states:.2f} | {seconds[False] / states:.2f} | "
              f"{seconds[False] / seconds[True]:.2f} | {same}/{args.scenes} |", flush=True)
    env.close()
    print(f"all: {total[True] / states_all:.2f} -> {total[False] / states_all:.2f} s per state "
          f"({total[False] / total[True]:.2f}x the time, {total[True] / total[False]:.2f}x the states per hour)")


if __name__ == "__main__":
    main()
