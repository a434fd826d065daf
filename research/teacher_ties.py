"""How often the teacher's choice has ties: labelled actions as good as the teacher's by the labels, off its square.

The distillation's teacher term (`sb3_pixeldqn.distill`) pushes every allowed action below the teacher's (its
square of ``--radius`` cells), including labelled actions that did as well by one step: they kept the scene valid
and sorted at least as many objects, where the teacher's sorted one. ``--teacher-set`` makes those part of the
target instead (`sb3_pixeldqn.distill.teacher_sets`, the same rule counted here). This counts, over a random sample
of shards, the states with a labelled teacher action, how many of those sorted an object, how many have at least one
such tie outside the teacher's square, the mean number of those ties per state and where they came from
(``label_source``).

    python -m research.teacher_ties data/teacher --max-shards s00:55,s01:50,s02:205,s03:602,s04:172,s05:419 \
        --shards 60 --seed 0 --out results/teacher_set/ties.md
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import cast

import numpy as np
import torch as th

from research import print_or_write
from sb3_pixeldqn.distill import near_cells, teacher_sets
from shelf_env.privileged import dataset


@dataclass
class Ties:
    """The counts of the module docstring."""

    states: int = 0  # states with a labelled teacher action
    sorted_one: int = 0  # ... whose teacher action sorted an object
    with_ties: int = 0  # ... with at least one tie off the teacher's square
    ties: int = 0  # ties in all
    sources: dict[str, int] = field(default_factory=lambda: {name: 0 for name in dataset.SOURCES})

    def table(self, shards: int, total: int, seed: int, radius: int) -> str:
        """The counts as a short markdown page."""
        n = max(self.states, 1)
        return "\n".join([
            f"# The teacher's ties ({shards} of {total} shards drawn at seed {seed}, square of {radius} cells)", "",
            "| states with a labelled teacher action | its action sorted an object | with a tie off its square | "
            "ties per state |", "|---|---|---|---|",
            f"| {self.states} | {100 * self.sorted_one / n:.1f} % | {100 * self.with_ties / n:.1f} % "
            f"| {self.ties / n:.2f} |", "",
            "Where the ties came from (`label_source`): " + ", ".join(f"{k} {v}" for k, v in self.sources.items()),
            ""])


def count_ties(shards: list[dataset.Shard], radius: int = 2) -> Ties:
    """The counts of the module docstring over ``shards`` (each state's labels as `dataset.labelled_states` reads
    them: progress = the change in sorted objects; masks are not needed)."""
    out = Ties()
    for shard in shards:
        labelled = dataset.labelled_states([shard], masks=False)
        assert labelled.label_progress is not None
        grid = (len(shard.meta["layout"]["map_names"]), *(int(g) for g in shard.arrays["obs"].shape[2:]))
        teacher = th.as_tensor(labelled.teacher_action)
        label_state, label_action = th.as_tensor(labelled.label_state), th.as_tensor(labelled.label_action)
        own = (label_action == teacher[label_state]).numpy() & (labelled.teacher_action[labelled.label_state] >= 0)
        rows = np.unique(labelled.label_state[own])
        if not len(rows):
            continue
        out.states += len(rows)
        out.sorted_one += len(np.unique(labelled.label_state[own & (labelled.label_progress > 0)
                                                             & ~labelled.label_invalid]))
        members = teacher_sets(th.as_tensor(rows), label_state, label_action, th.as_tensor(labelled.label_invalid),
                               th.as_tensor(labelled.label_progress), teacher, int(np.prod(grid)))  # the labels alone
        off = (members & ~near_cells(teacher[rows], grid, radius)).numpy()
        row_of = np.full(len(labelled.obs), -1)
        row_of[rows] = np.arange(len(rows))
        i = row_of[labelled.label_state]
        tie = (i >= 0) & off[np.maximum(i, 0), labelled.label_action]  # each tie once per label
        out.with_ties += len(np.unique(i[tie]))
        out.ties += int(tie.sum())
        per_source = np.bincount(shard.arrays["label_source"][tie], minlength=len(dataset.SOURCES))
        for name, n in zip(dataset.SOURCES, per_source):
            out.sources[name] += int(n)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m research.teacher_ties", description=__doc__.split("\n")[0])
    p.add_argument("data", type=pathlib.Path, help="the dataset folder")
    p.add_argument("--max-shards", default=None, help="draw from these shards only (as distil's --max-shards: "
                   "'s00:55,s01:9'), so that the draw stays the same while the dataset grows")
    p.add_argument("--shards", type=int, default=60, help="how many shards to draw (all where fewer)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draw")
    p.add_argument("--radius", type=int, default=2, help="the teacher's square, in cells (the recipe's 2)")
    p.add_argument("--out", type=pathlib.Path, default=None, help="write the page here (default: print it)")
    args = p.parse_args(argv)
    try:
        if args.shards < 1 or args.radius < 0:
            raise ValueError("--shards must be >= 1 and --radius >= 0")
        named = [SimpleNamespace(path=f) for f in dataset.shard_files(args.data)]  # selected by name, unread
        files = [s.path for s in dataset.select_shards(cast(list[dataset.Shard], named), args.max_shards)]
        if not files:
            raise ValueError(f"no dataset shards in {args.data}")
    except ValueError as err:
        print(f"teacher_ties: error: {err}", file=sys.stderr)
        return 2
    draw = sorted(np.random.default_rng(args.seed).choice(len(files), min(args.shards, len(files)), replace=False))
    counts = count_ties([dataset.load_shard(files[i]) for i in draw], args.radius)
    page = counts.table(len(draw), len(files), args.seed, args.radius)
    print_or_write(page, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
