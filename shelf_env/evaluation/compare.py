"""Two policies on the same scenes: their paired SR difference per N and pooled, with McNemar's exact test.

    python -m shelf_env.evaluation.compare results/distill_scaling/val90 --pair A B [--pair C D ...] \\
        [--out results/distill_scaling/val90.md]

Reads the episodes of a ``shelf-evaluate`` folder (its ``cells/``) and, for each ``--pair A B`` (policy labels
as the cells name them: a checkpoint's file stem), compares A with B on exactly the scenes both played at each
N: SR of each, A − B (SR points), and the scenes only A sorted (``A only``) and only B sorted (``B only``). A
scene both sorted or both failed says nothing about which is better; McNemar's exact test asks whether the
discordant scenes split more unevenly than a fair coin would (two-sided p). The last row of each pair pools its N,
and with several pairs (e.g. one recipe against another at two training seeds) a last table pools the pairs:
what a decision rule written over "both seeds pooled" reads. A pair whose policies share no scene at some N is
refused, naming them, rather than compared over different scenes.
"""

from __future__ import annotations

import argparse
import math
import pathlib
import sys
from dataclasses import dataclass

from shelf_env.evaluation.protocol import SceneIndex, by_scene, common_scenes, load_cells, scene_episodes
from shelf_env.files import write_text_atomically


@dataclass(frozen=True)
class Paired:
    """A against B on the same ``scenes`` (a count of paired episodes): each one's sorted scenes and the
    discordant ones."""

    scenes: int
    a_sorted: int
    b_sorted: int
    a_only: int
    b_only: int

    def __add__(self, other: Paired) -> Paired:
        return Paired(self.scenes + other.scenes, self.a_sorted + other.a_sorted, self.b_sorted + other.b_sorted,
                      self.a_only + other.a_only, self.b_only + other.b_only)

    @property
    def difference(self) -> float:
        """A's SR minus B's on these scenes (SR points)."""
        return 100.0 * (self.a_sorted - self.b_sorted) / self.scenes

    @property
    def p_value(self) -> float:
        """McNemar's exact two-sided p: the chance that a fair coin over the discordant scenes splits at least
        this unevenly (1 when there are none)."""
        return mcnemar_exact(self.a_only, self.b_only)


#: No scenes: the start of a sum of comparisons.
NOTHING = Paired(0, 0, 0, 0, 0)


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """Two-sided exact McNemar p-value of ``a_only`` against ``b_only`` discordant pairs (a binomial test at 1/2)."""
    if a_only < 0 or b_only < 0:
        raise ValueError(f"discordant counts must be >= 0, got {a_only} and {b_only}")
    total = a_only + b_only
    if total == 0:
        return 1.0
    tail = sum(math.comb(total, k) for k in range(min(a_only, b_only) + 1)) / 2**total
    return min(1.0, 2.0 * tail)


def paired(index: SceneIndex, a: str, b: str, n: int) -> Paired:
    """A against B on the scenes both played at N = ``n``; `ValueError` naming them when there are none."""
    scenes = common_scenes(index, [a, b], n)
    mine, theirs = scene_episodes(index, a, n, scenes), scene_episodes(index, b, n, scenes)
    if mine is None or theirs is None:
        played = sorted({p for p, m in index if m == n})
        raise ValueError(f"{a} and {b} share no scene at N = {n} (policies played there: {', '.join(played)})")
    return Paired(len(scenes), sum(r.success for r in mine), sum(r.success for r in theirs),
                  sum(x.success and not y.success for x, y in zip(mine, theirs, strict=True)),
                  sum(y.success and not x.success for x, y in zip(mine, theirs, strict=True)))


def compare(index: SceneIndex, pairs: list[tuple[str, str]]) -> dict[tuple[str, str], dict[int, Paired]]:
    """Each pair's comparison at every N where either of its policies played."""
    out: dict[tuple[str, str], dict[int, Paired]] = {}
    for a, b in pairs:
        ns = sorted({n for p, n in index if p in (a, b)})
        if not ns:
            names = sorted({p for p, _ in index})
            raise ValueError(f"neither {a} nor {b} is in the evaluation (its policies: {', '.join(names)})")
        out[(a, b)] = {n: paired(index, a, b, n) for n in ns}
    return out


def _row(label: str, c: Paired) -> str:
    return (f"| {label} | {c.scenes} | {100.0 * c.a_sorted / c.scenes:.1f} % | {100.0 * c.b_sorted / c.scenes:.1f} % "
            f"| {c.difference:+.1f} | {c.a_only} | {c.b_only} | {c.p_value:.3f} |")


HEADER = ("| N | scenes | SR A | SR B | A − B (points) | A only | B only | McNemar p |\n"
          "|---|---|---|---|---|---|---|---|")


def markdown(results: dict[tuple[str, str], dict[int, Paired]]) -> str:
    """One table per pair (a row per N, then pooled over N) and, with several pairs, one pooling them."""
    parts: list[str] = []
    for (a, b), by_n in results.items():
        pooled = sum(by_n.values(), NOTHING)
        parts += [f"**A = {a}, B = {b}**", "", HEADER, *(_row(str(n), c) for n, c in by_n.items()),
                  _row("pooled", pooled), ""]
    if len(results) > 1:
        ns = sorted({n for by_n in results.values() for n in by_n})
        rows = [_row(str(n), sum((by_n[n] for by_n in results.values() if n in by_n), NOTHING))
                for n in ns]
        everything = sum((c for by_n in results.values() for c in by_n.values()), NOTHING)
        parts += [f"**All {len(results)} pairs pooled** (A: {', '.join(a for a, _ in results)}; "
                  f"B: {', '.join(b for _, b in results)})", "", HEADER, *rows, _row("pooled", everything), ""]
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m shelf_env.evaluation.compare", description=__doc__.split("\n")[0])
    p.add_argument("folder", type=pathlib.Path, help="a shelf-evaluate folder (its cells/)")
    p.add_argument("--pair", nargs=2, action="append", required=True, metavar=("A", "B"),
                   help="two policy labels as the cells name them (repeat for more pairs)")
    p.add_argument("--out", type=pathlib.Path, default=None, help="also write the tables here (Markdown)")
    args = p.parse_args(argv)
    try:
        text = markdown(compare(by_scene(load_cells(args.folder)), [(a, b) for a, b in args.pair]))
    except ValueError as err:
        print(f"compare: error: {err}", file=sys.stderr)
        return 2
    print(text)
    if args.out is not None:
        write_text_atomically(args.out, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
