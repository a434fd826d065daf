"""What the dataset's driving models did in the states they led to: safe, and useful?

Every state of the teacher dataset labels the driving model's greedy masked action (source ``greedy``)
and the teacher's choice with their exact outcomes. Per shard series (one driver each) this prints how
often the driver's greedy action kept the scene valid, how often a valid one sorted at least one more
object, how often the teacher's choice did, and how often any labelled action did: whether a driver
fails by dropping objects or by not making progress.

    python research/driver_progress.py data/teacher
"""

from __future__ import annotations

import argparse
import pathlib
from typing import Any

from shelf_env.privileged import dataset


def series_rows(shards: list[dataset.Shard]) -> dict[str, dict[str, Any]]:
    """Per series (``s00``, ...): states, the driver (path and sha256 prefix of its shards' meta), and the shares
    of states where the greedy action was valid, where a valid greedy action made progress, where the teacher's
    choice made progress, and where some labelled valid action did."""
    greedy_source = dataset.SOURCES.index("greedy")
    rows: dict[str, dict[str, Any]] = {}
    for shard in shards:
        a = shard.arrays
        row = rows.setdefault(shard.path.name[:3], {"driver": shard.meta.get("model"),
                                                   "sha256": (shard.meta.get("model_sha256") or "")[:12],
                                                   "states": 0, "valid": 0, "greedy_progress": 0,
                                                   "teacher_progress": 0, "any_progress": 0})
        for t in range(shard.num_states):
            mine = a["label_state"] == t
            greedy = mine & (a["label_source"] == greedy_source)
            if greedy.sum() != 1:
                continue  # a state without a driver (collected with --model none)
            row["states"] += 1
            valid = bool(a["label_valid"][greedy][0])
            row["valid"] += valid
            row["greedy_progress"] += valid and int(a["label_dsorted"][greedy][0]) > 0
            teacher = mine & (a["label_action"] == a["teacher_action"][t]) & a["label_valid"]
            row["teacher_progress"] += bool((a["label_dsorted"][teacher] > 0).any())
            row["any_progress"] += bool((a["label_dsorted"][mine & a["label_valid"]] > 0).any())
    return rows


def table(rows: dict[str, dict[str, Any]]) -> str:
    lines = ["| series | driver | states | greedy valid | valid greedy sorted one | teacher sorted one | "
             "some labelled action sorted one |", "|---|---|---|---|---|---|---|"]
    for name, r in sorted(rows.items()):
        n = max(r["states"], 1)
        driver = f"{pathlib.Path(str(r['driver'])).name}" + (f" ({r['sha256']})" if r["sha256"] else "")
        lines.append(f"| {name} | {driver} | {r['states']} | {r['valid'] / n:.1%} | "
                     f"{r['greedy_progress'] / max(r['valid'], 1):.1%} | {r['teacher_progress'] / n:.1%} | "
                     f"{r['any_progress'] / n:.1%} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", type=pathlib.Path, nargs="?", default=pathlib.Path("data/teacher"))
    args = p.parse_args(argv)
    print(table(series_rows(dataset.load_dataset(args.folder))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
