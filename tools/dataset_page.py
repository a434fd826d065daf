"""Write the teacher dataset's numbers into its pages from the committed shards, so that they are derived, not pasted.

The dataset grows every session; its experiment page (docs/experiments/teacher-dataset.md) and CHANGELOG.md
quote what it holds. This tool counts the shards (`shelf_env.privileged.dataset.summarize`) and rewrites:

- the page's status block, between ``<!-- dataset status: begin -->`` and ``<!-- dataset status: end -->``: the
  output of ``python -m shelf_env.privileged.dataset status data/teacher``, when the newest shard was collected and
  how large the shards are;
- the page's projection, between ``<!-- dataset projection: begin -->`` and ``<!-- dataset projection: end -->``:
  the share of the ~100,000 states aimed at and how long the rest takes at the last session's rate (read from the
  page's per-session throughput rows);
- the sentences that quote the totals: "The dataset holds N states (P % of" in the page's verdict and "The teacher
  dataset holds N states, L labels in S shards (P % of" in CHANGELOG.md.

With ``--session K --since SPEC --note TEXT`` it first adds session K's rows to the page's throughput table, one
per series, counted by ``status --since SPEC`` (SPEC: the previous session's last ``--max-shards`` spec).

Only the shards git tracks are counted where the folder is in a git work tree, so that a page written while a
collector adds shards still describes what a clean clone holds.

    python tools/dataset_page.py                    # rewrite the page and CHANGELOG.md
    python tools/dataset_page.py --check            # exit 1 if either is not what it would write
    python tools/dataset_page.py --session 37 --since s03:799,s05:718 --note "s03 and s05 for two hours"
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import pathlib
import re
import subprocess
import sys
import textwrap

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from shelf_env.privileged.dataset import DatasetSummary, format_status, summarize  # noqa: E402

AIM = 100_000  # the aim, in labelled states
WIDTH = 118  # the page's line length
STATUS = ("<!-- dataset status: begin -->", "<!-- dataset status: end -->")
PROJECTION = ("<!-- dataset projection: begin -->", "<!-- dataset projection: end -->")
TABLE_HEADER = ("| session | series | shards | states | labels | worker-hours | states / labels per worker-hour "
                "| the cores |")
ROW = re.compile(r"^\| (\d+)(?:st|nd|rd|th) \| s\d\d \| [\d,]+ \| ([\d,]+) \| [\d,]* \| ~?([\d.]+) \|", re.M)
VERDICT = re.compile(r"The dataset holds [\d,]+ states \([\d.]+ % of")
CHANGELOG = re.compile(r"The teacher dataset holds [\d,]+ states, [\d,]+ labels in [\d,]+ shards \([\d.]+ % of")
WORDS = {1: "first", 2: "second", 3: "third", 4: "fourth", 5: "fifth", 6: "sixth", 7: "seventh", 8: "eighth",
         9: "ninth", 10: "tenth", 11: "eleventh", 12: "twelfth", 13: "thirteenth", 14: "fourteenth",
         15: "fifteenth", 16: "sixteenth", 17: "seventeenth", 18: "eighteenth", 19: "nineteenth", 20: "twentieth",
         30: "thirtieth", 40: "fortieth", 50: "fiftieth"}
TENS = {20: "twenty", 30: "thirty", 40: "forty", 50: "fifty"}


def ordinal(k: int) -> str:
    """``37`` -> ``37th``, as the throughput table names a session."""
    suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
    return f"{k}{suffix}"


def ordinal_words(k: int) -> str:
    """``26`` -> ``twenty-sixth``, as the page's prose names a session (1..59)."""
    if k in WORDS:
        return WORDS[k]
    if not 0 < k < 60:
        raise ValueError(f"no words for session {k}")
    return f"{TENS[k // 10 * 10]}-{WORDS[k % 10]}"


def committed(folder: pathlib.Path) -> set[str] | None:
    """The shard names git tracks in ``folder`` (staged ones included); None where ``folder`` is not in a work tree."""
    try:
        out = subprocess.run(["git", "ls-files", "--", "."], cwd=folder, capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return {pathlib.PurePath(line).name for line in out.stdout.splitlines() if line.endswith(".npz")}


def between(text: str, markers: tuple[str, str], body: str, where: str) -> str:
    """``text`` with what lies between the two marker lines replaced by ``body``; a `ValueError` naming ``where``
    and the marker when one is missing or they come in the wrong order."""
    begin, end = markers
    i, j = text.find(begin), text.find(end)
    if i < 0 or j < 0 or j < i:
        raise ValueError(f"{where} has no '{begin}' ... '{end}' block")
    return text[: i + len(begin)] + "\n" + body + "\n" + text[j:]


def sub_once(pattern: re.Pattern[str], text: str, new: str, where: str) -> str:
    out, n = pattern.subn(new, text)
    if n != 1:
        raise ValueError(f"{where} quotes the dataset's totals {n} times where one was expected ({pattern.pattern!r})")
    return out


def session_rows(text: str) -> dict[int, list[tuple[int, float]]]:
    """The throughput table's rows per session: (states, worker-hours); rows spanning sessions are skipped."""
    rows: dict[int, list[tuple[int, float]]] = {}
    for m in ROW.finditer(text):
        rows.setdefault(int(m.group(1)), []).append((int(m.group(2).replace(",", "")), float(m.group(3))))
    return rows


def add_session(text: str, session: int, since: DatasetSummary, note: str, where: str) -> str:
    """``text`` with one throughput row per series of ``since`` (a `summarize` with ``since`` set) for ``session``,
    after the table's last row; a `ValueError` where the session already has rows or the table is missing."""
    if since.since is None:
        raise ValueError("a session's rows count the shards after a --since spec; none was given")
    if not since.per_series:
        raise ValueError(f"no shards after {since.since}: session {session} collected nothing to add")
    if session in session_rows(text):
        raise ValueError(f"{where} already has rows for the {ordinal(session)} session")
    start = text.find(TABLE_HEADER)
    if start < 0:
        raise ValueError(f"{where} has no throughput table ({TABLE_HEADER!r})")
    end = text.find("\n\n", start)
    rows = []
    for i, (name, r) in enumerate(sorted(since.per_series.items())):
        hours = r[3] / 3600
        cell = note + f"; `--since {since.since}`" if i == 0 else "as above"
        rows.append(f"| {ordinal(session)} | {name} | {r[0]:,.0f} | {r[1]:,.0f} | {r[2]:,.0f} | {hours:.2f} | "
                    f"**{r[1] / hours:,.0f} / {r[2] / hours:,.0f}** | {cell} |")
    return text[:end] + "\n" + "\n".join(rows) + text[end:]


def status_block(summary: DatasetSummary, status_text: str, megabytes: float) -> str:
    when = f"the newest shard collected {summary.collected}; " if summary.collected else ""
    return (wrap(f"What it holds (`python tools/dataset_page.py` writes this block from `python -m "
                 f"shelf_env.privileged.dataset status data/teacher`; {when}one or two collection processes on 2 CPU "
                 f"cores beside other work, so the worker-hour rates undercount an idle core's; the shards committed "
                 f"in `data/teacher/`, {megabytes:.0f} MB):") + f"\n\n```\n{status_text}\n```")


def projection(summary: DatasetSummary, text: str) -> str:
    """The paragraph on what is left to collect, at the rate of the last session in the throughput table."""
    rows = session_rows(text)
    if not rows:
        raise ValueError("the throughput table has no per-session rows to take a rate from")
    last = max(rows)
    rate = sum(r[0] for r in rows[last]) / sum(r[1] for r in rows[last])
    share = summary.states / AIM
    left = max(AIM - summary.states, 0)
    recent = [sum(r[0] for r in rows[k]) for k in rows if k >= 26]
    spread = (f" (the rows above: from {min(recent):,} to {max(recent):,} states a session since the twenty-sixth,"
              " most of them beside other work)") if recent else ""
    if left == 0:
        return wrap(f"The dataset holds {summary.states:,} states, {share * 100:.1f} % of the ~{AIM:,} aimed at.")
    hours = left / (2 * rate)
    return wrap(
        f"The dataset holds {summary.states:,} states, {share * 100:.1f} % of the ~{AIM:,} states aimed at. At the "
        f"{ordinal_words(last)} session's rate ({rate:,.0f} states per worker-hour, its rows above) the remaining "
        f"{left:,} take about {math.ceil(hours)} hours of both cores, some {math.ceil(hours / 2)} sessions that leave "
        f"the cores to the collectors for two hours or more{spread}; beside a distillation or evaluation the rate "
        f"halves or worse. 16 workers (`--workers 16`), if they scaled linearly, would take about "
        f"{left / (16 * rate):.1f} hours.")


def wrap(paragraph: str) -> str:
    return textwrap.fill(paragraph, WIDTH, break_long_words=False, break_on_hyphens=False)


def rewrite(page: str, changelog: str, summary: DatasetSummary, status_text: str, megabytes: float,
            page_name: str = "the page", changelog_name: str = "CHANGELOG.md") -> tuple[str, str]:
    """The page and the changelog with every quoted number taken from ``summary``."""
    share = summary.states / AIM * 100
    page = between(page, STATUS, status_block(summary, status_text, megabytes), page_name)
    page = between(page, PROJECTION, projection(summary, page), page_name)
    page = sub_once(VERDICT, page, f"The dataset holds {summary.states:,} states ({share:.1f} % of", page_name)
    changelog = sub_once(CHANGELOG, changelog, f"The teacher dataset holds {summary.states:,} states, "
                         f"{summary.labels:,} labels in {summary.shards:,} shards ({share:.1f} % of", changelog_name)
    return page, changelog


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=pathlib.Path, default=ROOT / "data" / "teacher", help="the dataset folder")
    parser.add_argument("--page", type=pathlib.Path, default=ROOT / "docs" / "experiments" / "teacher-dataset.md")
    parser.add_argument("--changelog", type=pathlib.Path, default=ROOT / "CHANGELOG.md")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a file is not what it would be")
    parser.add_argument("--session", type=int, default=None, help="add this session's throughput rows first")
    parser.add_argument("--since", default=None, help="with --session: the previous session's --max-shards spec")
    parser.add_argument("--note", default=None, help="with --session: what else ran on the cores")
    args = parser.parse_args(argv)
    try:
        if args.session is not None and (args.check or args.since is None or args.note is None):
            raise ValueError("--session needs --since and --note, and does not go with --check")
        names = committed(args.data)
        if names is not None and not names:
            raise ValueError(f"git tracks no shard in {args.data}")
        summary = summarize(args.data, names=names)
        page, changelog = args.page.read_text(), args.changelog.read_text()
        new_page = page
        if args.session is not None:
            new_page = add_session(page, args.session, summarize(args.data, args.since, names=names), args.note,
                                   str(args.page))
        shown = "data/teacher" if args.data.resolve() == (ROOT / "data" / "teacher").resolve() else str(args.data)
        text = format_status(dataclasses.replace(summary, folder=pathlib.Path(shown)))  # named as the command names it
        new_page, new_changelog = rewrite(new_page, changelog, summary, text, summary.size_bytes / 1e6, str(args.page),
                                          str(args.changelog))
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    stale = [(path, new) for path, old, new in ((args.page, page, new_page), (args.changelog, changelog, new_changelog))
             if old != new]
    if args.check:
        for path, _ in stale:
            print(f"{path} is stale: run python tools/dataset_page.py", file=sys.stderr)
        return 1 if stale else 0
    for path, new in stale:
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(new)
        tmp.replace(path)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
