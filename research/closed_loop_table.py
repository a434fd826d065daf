"""Issue 13's fall table from shelf-evaluate folders: per policy and N, sorted episodes and episodes
with a fall in each folder, and the change of falls over N = 8..14 and of sorted episodes over
N = 3..5 against the first folder (the open loop).

    python research/closed_loop_table.py results/closed_loop_seed0/off results/closed_loop_seed0/on \\
        --out results/closed_loop_seed0/table.md

Each folder's watch (its ``conditions.json``) is printed under the table. ``--policies`` and
``--seeds`` keep only those records (e.g. a policy evaluated on fewer seeds in one folder than in
another: compare it on the seeds both have). A comparison column is ``-`` where the folder or the
first one lacks a cell of its N range, or the two have different numbers of runs in one (a grid
still being evaluated).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from collections import Counter

from shelf_env.evaluation import protocol as ev
from shelf_env.files import write_text_atomically


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=pathlib.Path, help="the open loop first")
    parser.add_argument("--out", type=pathlib.Path, default=None)
    parser.add_argument("--policies", nargs="+", default=None, help="policy labels to keep (default: all)")
    parser.add_argument("--seeds", nargs="+", type=int, default=None, help="evaluation seeds to keep (default: all)")
    args = parser.parse_args(argv)
    try:
        records = {f: ev.load_cells(f) for f in args.folders}
    except ValueError as err:
        print(f"closed_loop_table: error: {err}", file=sys.stderr)
        return 2
    sorted_: Counter = Counter()
    fell: Counter = Counter()
    runs: Counter = Counter()
    for folder, recs in records.items():
        for r in recs:
            if (args.policies is not None and r.policy not in args.policies) or \
                    (args.seeds is not None and r.seed not in args.seeds):
                continue
            key = (folder.name, r.policy, r.num_objects)
            runs[key] += 1
            sorted_[key] += r.success
            fell[key] += r.fell
    policies = sorted({key[1] for key in runs})
    ns = sorted({key[2] for key in runs})
    names = [f.name for f in args.folders]
    kept = "".join(f"; {what} {', '.join(map(str, values))} only" for what, values in
                   (("policies", args.policies), ("seeds", args.seeds)) if values is not None)
    lines = ["Sorted / episodes with a fall, of the runs per cell; the last two columns compare each folder "
             f"with `{names[0]}`{kept}.", "",
             "| folder | policy | " + " | ".join(f"N = {n}" for n in ns) + " | falls N = 8..14 | sorted N = 3..5 |",
             "|---|---|" + "---|" * (len(ns) + 2)]
    for name in names:
        for policy in policies:
            if not any(runs[(name, policy, n)] for n in ns):
                continue  # not evaluated in this folder
            cells = [f"{sorted_[(name, policy, n)]} / {fell[(name, policy, n)]}" if runs[(name, policy, n)] else "-"
                     for n in ns]
            falls, base_falls = (sum(fell[(f, policy, n)] for n in ns if 8 <= n <= 14) for f in (name, names[0]))
            won, base_won = (sum(sorted_[(f, policy, n)] for n in ns if 3 <= n <= 5) for f in (name, names[0]))
            change = f"{falls} ({100 * (falls - base_falls) / base_falls:+.0f} %)" if base_falls else str(falls)
            gain = f"{won} ({won - base_won:+d})"
            for lo, hi in ((8, 14), (3, 5)):
                span = [n for n in ns if lo <= n <= hi]
                if not all(runs[(name, policy, n)] == runs[(names[0], policy, n)] > 0 for n in span):
                    change, gain = ("-", gain) if lo == 8 else (change, "-")
            lines.append(f"| {name} | {policy} | " + " | ".join(cells) + f" | {change} | {gain} |")
    lines += ["", "Watches (`conditions.json`):", ""]
    for folder in args.folders:
        path = folder / "conditions.json"
        conditions = json.loads(path.read_text()) if path.exists() else {}
        lines.append(f"- `{folder.name}`: {json.dumps(conditions.get('closed_loop', 'open loop'))}")
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out is not None:
        write_text_atomically(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
