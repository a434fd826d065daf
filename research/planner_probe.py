"""The planning teacher's first probe beside the policies already evaluated on the same scenes.

    python research/planner_probe.py results/planning_teacher --against results/privileged_ceiling_open \\
        results/models --out results/planning_teacher/report.md

For every (N, seed, run) that the planner's folder holds, the same episode's record of every policy
in the ``--against`` folders (their cells: the same scene seeds), as a table: sorted or how it
ended, actions, and the planner's env actions per decision. Writes the table to ``--out``.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from shelf_env.evaluation.protocol import load_cells
from shelf_env.files import write_text_atomically


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("folder", type=pathlib.Path, help="the planner's evaluation folder")
    p.add_argument("--against", type=pathlib.Path, nargs="+", required=True, help="evaluation folders to compare")
    p.add_argument("--out", type=pathlib.Path, required=True, help="the markdown table to write")
    args = p.parse_args(argv)
    try:
        mine = load_cells(args.folder)
        others = [r for f in args.against for r in load_cells(f)]
    except ValueError as err:
        print(f"planner_probe: error: {err}", file=sys.stderr)
        return 2
    keys = sorted({(r.num_objects, r.seed, r.run) for r in mine})
    policies = sorted({r.policy for r in mine} | {r.policy for r in others if (r.num_objects, r.seed, r.run) in keys})
    by = {(r.policy, r.num_objects, r.seed, r.run): r for r in [*others, *mine]}
    rows = ["| N | seed | run | " + " | ".join(policies) + " |", "|---|---|---|" + "---|" * len(policies)]
    for n, seed, run in keys:
        cells = []
        for policy in policies:
            r = by.get((policy, n, seed, run))
            cells.append("-" if r is None else f"{'sorted' if r.success else r.failure or 'failed'} in {r.actions}")
        rows.append(f"| {n} | {seed} | {run} | " + " | ".join(cells) + " |")
    stats = [r.policy_stats for r in mine if r.policy_stats]
    decisions = sum(s.get("decisions", 0) + s.get("uncover_decisions", 0) for s in stats)
    actions = sum(s.get("actions", 0) for s in stats)
    command = " ".join(["python research/planner_probe.py", *(sys.argv[1:] if argv is None else argv)])
    text = (f"Sorted (or how the episode ended) and actions, the same scenes for every policy (`{command}`):\n\n"
            + "\n".join(rows) + f"\n\nThe planner spent {actions / max(decisions, 1):.1f} env actions per decision "
            f"({decisions} decisions).\n")
    write_text_atomically(args.out, text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
