"""The planning teacher's first probe beside the policies already evaluated on the same scenes.

    python research/planner_probe.py results/planning_teacher --against results/privileged_ceiling_open \\
        results/models --out results/planning_teacher/report.md

For every (N, seed, run) that the planner's folder holds, the same episode's record of every policy
in the ``--against`` folders (their cells: the same scene seeds), as a table: sorted or how it
ended, actions, and the planner's env actions per decision. Above it, per N, each policy's scenes
sorted and dropped out of those the planner played (`summary`; "-" for a policy that lacks one of
them: its count would be over other scenes), with the planner's env actions per decision and its margin
over the best of the ``--heuristics`` on those scenes (SR points: the planner's SR minus the better
heuristic's, per N), and that margin averaged over the N where every heuristic played every scene.
Writes the tables to ``--out``.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from shelf_env.evaluation.protocol import (
    EpisodeRecord,
    SceneIndex,
    by_scene,
    load_cells,
    margin_over_best,
    scene_episodes,
)
from shelf_env.files import write_text_atomically


def planner_actions(records: list[EpisodeRecord]) -> tuple[int, int]:
    """(env actions, decisions) the planner's ``records`` spent (its ``policy_stats``)."""
    stats = [r.policy_stats for r in records if r.policy_stats]
    decisions = sum(s.get("decisions", 0) + s.get("uncover_decisions", 0) for s in stats)
    return sum(s.get("actions", 0) for s in stats), decisions


def summary(mine: list[EpisodeRecord], by: SceneIndex, policies: list[str],
            heuristics: list[str] | None = None) -> list[str]:
    """Markdown rows: per N, each policy's "sorted k / n (fell f)" over the planner's scenes at that N, the
    planner's env actions per decision there and, with ``heuristics``, the planner's margin over the better
    of them (SR points; "-" where one lacks a scene), then a line with that margin averaged over the N that
    have one; ``by``: every episode by (policy, N) and scene (`by_scene`). A policy missing one of those scenes
    shows "-"."""
    planner = sorted({r.policy for r in mine})[0]
    margin_head = f" margin over the best of {', '.join(heuristics)} (points) |" if heuristics else ""
    rows = ["| N | scenes | " + " | ".join(policies) + " | planner env actions per decision |" + margin_head,
            "|---|---|" + "---|" * (len(policies) + 1 + bool(heuristics))]
    margins: dict[int, float] = {}
    for n in sorted({r.num_objects for r in mine}):
        scenes = sorted({(r.seed, r.run) for r in mine if r.num_objects == n})
        cells = []
        for policy in policies:
            done = scene_episodes(by, policy, n, scenes)
            cells.append("-" if done is None else
                         f"{sum(r.success for r in done)} / {len(done)} (fell {sum(r.fell for r in done)})")
        actions, decisions = planner_actions([r for r in mine if r.num_objects == n])
        margin = ""
        if heuristics:
            paired = margin_over_best(by, planner, n, scenes, heuristics)
            if paired is not None:
                margins[n] = paired["margin"]
            margin = f" {margins[n]:+.1f} |" if n in margins else " - |"
        rows.append(f"| {n} | {len(scenes)} | " + " | ".join(cells) + f" | {actions / max(decisions, 1):.1f} |"
                    + margin)
    if heuristics:
        average = f"{sum(margins.values()) / len(margins):+.1f} points" if margins else "none"
        rows += ["", f"{planner}'s margin over the best of {', '.join(heuristics)} averaged over the "
                 f"{len(margins)} N measured ({', '.join(map(str, margins))}): {average}."]
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("folder", type=pathlib.Path, help="the planner's evaluation folder")
    p.add_argument("--against", type=pathlib.Path, nargs="+", required=True, help="evaluation folders to compare")
    p.add_argument("--out", type=pathlib.Path, required=True, help="the markdown table to write")
    p.add_argument("--policies", nargs="+", default=None, help="the compared policies' columns, in this order "
                   "(default: every policy of the --against folders that played one of the planner's scenes)")
    p.add_argument("--heuristics", nargs="*", default=["h-d", "h-a"],
                   help="the planner's margin is over the best of these per N (default: h-d h-a; none: no margin)")
    args = p.parse_args(argv)
    try:
        mine = load_cells(args.folder)
        others = [r for f in args.against for r in load_cells(f)]
    except ValueError as err:
        print(f"planner_probe: error: {err}", file=sys.stderr)
        return 2
    keys = sorted({(r.num_objects, r.seed, r.run) for r in mine})
    played = {r.policy for r in others if (r.num_objects, r.seed, r.run) in keys}
    if args.policies is not None and not set(args.policies) <= played:
        print(f"planner_probe: error: no record of {sorted(set(args.policies) - played)} on the planner's scenes "
              f"(policies there: {sorted(played)})", file=sys.stderr)
        return 2
    policies = sorted({r.policy for r in mine}) + (args.policies if args.policies is not None else sorted(played))
    by = by_scene([*others, *mine])
    rows = ["| N | seed | run | " + " | ".join(policies) + " |", "|---|---|---|" + "---|" * len(policies)]
    for n, seed, run in keys:
        cells = []
        for policy in policies:
            r = by.get((policy, n), {}).get((seed, run))
            cells.append("-" if r is None else f"{'sorted' if r.success else r.failure or 'failed'} in {r.actions}")
        rows.append(f"| {n} | {seed} | {run} | " + " | ".join(cells) + " |")
    actions, decisions = planner_actions(mine)
    command = " ".join(["python research/planner_probe.py", *(sys.argv[1:] if argv is None else argv)])
    text = (f"Scenes sorted (and dropped), the same scenes for every policy (`{command}`):\n\n"
            + "\n".join(summary(mine, by, policies, args.heuristics))
            + "\n\nPer scene, sorted (or how the episode ended) and actions:\n\n"
            + "\n".join(rows) + f"\n\nThe planner spent {actions / max(decisions, 1):.1f} env actions per decision "
            f"({decisions} decisions).\n")
    write_text_atomically(args.out, text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
