"""How the privileged lookahead's evaluation episodes ended invalid (an analysis of `shelf_env.privileged.lookahead`).

    python -m research.lookahead_falls results/lookahead     (writes <folder>/invalid_steps.md)
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from shelf_env.evaluation.protocol import EpisodeRecord, load_cells
from shelf_env.files import write_atomically


def invalid_step_table(records: list[EpisodeRecord]) -> str:
    """Markdown: per lookahead policy and N, how its episodes that ended invalid (a fall or an
    unstable scene) got there, from the records' ``policy_stats``: at a sorting step where every
    visible unsorted object's pick was invalid, at an uncovering step where every visible object's
    pick was (and every probed push, both), or at an unprobed step (none expected: the empty-view
    pick touches nothing); with the vetoes (the base's choice was invalid, another pick was not) and
    push rescues (every pick invalid, a push not) per episode."""
    rows = ["| policy | N | episodes | ended invalid | no valid pick or push at a sorting step "
            "| ... at an uncovering step | unprobed | vetoes / episode | push rescues / episode | probes / action |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict[tuple[str, int], list[EpisodeRecord]] = {}
    for r in records:
        if r.policy_stats:
            groups.setdefault((r.policy, r.num_objects), []).append(r)
    if not groups:
        raise ValueError("no record carries lookahead stats (policy_stats): evaluate h-d-lookahead or "
                         "h-a-lookahead with this version")
    for (policy, n), rs in sorted(groups.items()):
        invalid = [r for r in rs if r.failure in ("fell", "unstable")]
        sorting = sum(r.policy_stats.get("unavoidable", 0) > 0 for r in invalid)
        uncover = sum(r.policy_stats.get("uncover_unavoidable", 0) > 0 for r in invalid)
        vetoes = sum(r.policy_stats.get("vetoes", 0) + r.policy_stats.get("uncover_vetoes", 0) for r in rs)
        rescues = sum(r.policy_stats.get("push_rescues", 0) for r in rs)
        probes = sum(r.policy_stats.get("probes", 0) for r in rs)
        rows.append(f"| {policy} | {n} | {len(rs)} | {len(invalid)} | {sorting} | {uncover} "
                    f"| {len(invalid) - sorting - uncover} | {vetoes / len(rs):.2f} | {rescues / len(rs):.2f} "
                    f"| {probes / max(1, sum(r.actions for r in rs)):.2f} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.lookahead_falls",
                                     description="How the lookahead's invalid episodes ended (writes "
                                                 "<folder>/invalid_steps.md)")
    parser.add_argument("folder", type=pathlib.Path, help="a shelf-evaluate --out folder with lookahead cells")
    args = parser.parse_args(argv)
    try:
        table = invalid_step_table(load_cells(args.folder))
    except ValueError as err:
        print(f"lookahead: error: {err}", file=sys.stderr)
        return 2
    command = " ".join(["python -m research.lookahead_falls", *(sys.argv[1:] if argv is None else argv)])
    text = f"How the lookahead's episodes ended invalid (`{command}`):\n\n{table}"
    write_atomically(args.folder / "invalid_steps.md", lambda tmp: tmp.write_text(text))
    print(table, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
