"""What each shard series of the teacher dataset holds: which primitive the teacher chose and which was executed.

The series differ by their driver (`data/drivers/README.md`): the executed action is the teacher's, or, with
``explore``, the driver's greedy action where its probe kept the scene valid. A series whose driver pushes where the
teacher would pick holds states the other series do not reach; distilling on it (docs/experiments/own-states.md,
candidates B and C) trains the Q-maps there. Per series: states, the share of the teacher's choices and of the
executed actions that are pushes, how often the executed action is the teacher's, and how often the driver's greedy
action (its label, source ``greedy``) drops an object.

    python -m research.series_actions data/teacher --out results/own_states/series_actions.md
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

from research import table_command
from shelf_env.privileged import dataset


def series_table(folder: pathlib.Path) -> str:
    """A markdown table, one row per shard series of ``folder`` (shards checked as `dataset.load_shard` does)."""
    greedy = dataset.SOURCES.index("greedy")
    rows: dict[str, np.ndarray] = {}
    for path in dataset.shard_files(folder):
        shard = dataset.load_shard(path)
        arrays = shard.arrays
        cells = int(np.prod(arrays["obs"].shape[2:]))
        pick = list(shard.meta["layout"]["map_names"]).index("pick")  # every other map is a push
        teacher, executed = arrays["teacher_action"], arrays["executed_action"]
        probed = arrays["label_source"] == greedy
        pushed = (executed >= 0) & (executed // cells != pick)  # -1: nothing was executed (no valid action)
        counts = np.array([len(teacher), (teacher // cells != pick).sum(), pushed.sum(),
                           (teacher == executed).sum(), probed.sum(), arrays["label_fell"][probed].sum()], float)
        series = path.name[:3]
        rows[series] = rows.get(series, np.zeros(6)) + counts
    if not rows:
        raise ValueError(f"no dataset shards (sNN_NNNNN.npz) in {folder}")
    lines = ["| series | states | teacher's choice a push | executed a push | executed = teacher's | "
             "driver's greedy action drops an object |", "|---|---|---|---|---|---|"]
    for series, (n, t_push, e_push, same, g, g_fell) in sorted(rows.items()):
        fell = f"{100 * g_fell / g:.1f} % of {int(g)}" if g else "-"
        lines.append(f"| {series} | {int(n)} | {100 * t_push / n:.1f} % | {100 * e_push / n:.1f} % | "
                     f"{100 * same / n:.1f} % | {fell} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", type=pathlib.Path, help="the dataset folder")
    parser.add_argument("--out", type=pathlib.Path, help="write the table here (else print it)")
    args = parser.parse_args(argv)
    return table_command(lambda: series_table(args.data), args.out)


if __name__ == "__main__":
    sys.exit(main())
