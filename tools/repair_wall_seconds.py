"""One-off repair of runs made by examples/train.py before commit "train.py: count wall time once".

That version added the whole session's elapsed time to the total already saved at the last
checkpoint, so after the k-th checkpoint the recorded wall time was R_k = R_{k-1} + t_k (t_k the
real time since the process started) instead of t_k. The checkpoint lines of the run's log
("[  R min] checkpoint at step S") give every R_k (to 0.1 min); from them this rewrites
``progress.json``'s ``wall_seconds`` (= t of the last checkpoint) and the ``wall_seconds`` column of
``episodes.csv`` (row value minus the R of the last checkpoint before it). Accurate to ~6 s.

    python tools/repair_wall_seconds.py runs/curriculum runs/curriculum.log
"""

from __future__ import annotations

import csv
import json
import pathlib
import re
import sys


def main(run: pathlib.Path, log: pathlib.Path) -> None:
    pattern = r"\[\s*([\d.]+) min\] checkpoint at step (\d+)"
    marks = [(float(m), int(s)) for m, s in re.findall(pattern, log.read_text())]
    recorded = [60.0 * m for m, _ in marks]  # R_k
    steps = [s for _, s in marks]
    progress_path = run / "progress.json"
    progress = json.loads(progress_path.read_text())
    if progress.get("wall_seconds_repaired"):
        print("already repaired")
        return
    real_last = recorded[-1] - (recorded[-2] if len(recorded) > 1 else 0.0)
    with open(run / "episodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))[: progress["episodes"]]  # rows after the checkpoint are redone
    for row in rows:
        before = [r for r, s in zip(recorded, steps) if s < int(row["timestep"])]
        offset = before[-1] if before else 0.0
        # rows were written as R_(k) + t, with R_(0) = 0 before the first checkpoint
        row["wall_seconds"] = f"{float(row['wall_seconds']) - offset:.1f}"
    with open(run / "episodes.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    progress["wall_seconds"] = round(real_last, 1)
    progress["wall_seconds_repaired"] = True
    progress_path.write_text(json.dumps(progress, indent=1))
    print(f"{run}: wall_seconds {recorded[-1]:.0f} -> {real_last:.0f}")


if __name__ == "__main__":
    main(pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2]))
