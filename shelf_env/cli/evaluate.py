"""Evaluate policies on ShelfSort-v0 with the paper's protocol (§V) and plot Fig. 10 / Fig. 12.

    shelf-evaluate --policies h-d h-a random --ns 3-14 --runs 20 --seeds 2 \\
        --object-sets ycb --out results/baselines --workers 2

Policies: ``h-d``, ``h-a``, ``random`` or a PixelDoubleDQN checkpoint zip (its P+S or S layout
decides the env's primitives). Every (policy, object set, N, seed) cell runs in a worker process
and is written to ``<out>/cells/`` as soon as it finishes; running the same command again skips
the cells already on disk, so an interrupted evaluation resumes. At the end (or with
``--summarize-only``) it writes ``results.csv``, ``results.json`` (with this configuration) and
``sr_ae_mae_<set>.png`` (Fig. 10), plus ``train_vs_test.png`` (Fig. 12) when both object sets
were evaluated.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import pathlib
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed

from tqdm import tqdm

from shelf_env import evaluation as ev


def parse_ns(text: str) -> list[int]:
    """"3-14" or "3,5,8" -> list of ints."""
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            lo, hi = part.split("-")
            out += list(range(int(lo), int(hi) + 1))
        else:
            out.append(int(part))
    return out


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="shelf-evaluate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--policies", nargs="+", required=True, help="h-d, h-a, random or checkpoint .zip paths")
    p.add_argument("--ns", type=parse_ns, default=list(range(3, 15)), help="e.g. 3-14 or 3,5,8")
    p.add_argument("--runs", type=int, default=100, help="episodes per (policy, N, seed) (paper: 100)")
    p.add_argument("--seeds", type=int, default=5, help="number of seeds, 0..S-1 (paper: 5)")
    p.add_argument("--object-sets", nargs="+", choices=["ycb", "train"], default=["ycb"])
    p.add_argument("--out", type=pathlib.Path, required=True)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--summarize-only", action="store_true", help="only aggregate the cells already on disk")
    return p.parse_args(argv)


def _run_cell(policy: str, n: int, seed: int, runs: int, object_set: str, path: str, parent_pid: int) -> bool:
    """Run one cell and write it; True if written. A worker whose parent died meanwhile (the
    evaluation was killed, maybe to change the code) discards its cell instead of writing it."""
    import torch

    torch.set_num_threads(1)
    records = ev.evaluate_cell(policy, n, seed, runs, object_set)
    if os.getppid() != parent_pid:
        return False
    ev.save_cell(pathlib.Path(path), records)
    return True


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:  # every bad input is reported before any episode runs, in one line
        for policy in args.policies:
            ev.check_policy(policy)
        ns = ev.check_ns(args.ns)
        if args.runs < 1 or args.seeds < 1 or args.workers < 1:
            raise ValueError("--runs, --seeds and --workers must be >= 1")
    except ValueError as err:
        print(f"shelf-evaluate: error: {err}", file=sys.stderr)
        return 2
    jobs = [
        (policy, n, seed, object_set)
        for n in ns for seed in range(args.seeds) for object_set in args.object_sets for policy in args.policies
    ]
    paths = {job: ev.cell_path(args.out, job[0], job[3], job[1], job[2], args.runs) for job in jobs}
    todo = [job for job in jobs if not paths[job].exists()]
    print(f"{len(jobs)} cells, {len(jobs) - len(todo)} already on disk, {len(todo)} to run", flush=True)
    if todo and not args.summarize_only:
        ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(max_workers=args.workers, mp_context=ctx) as pool:
            futures = [pool.submit(_run_cell, p, n, s, args.runs, o, str(paths[(p, n, s, o)]), os.getpid())
                       for p, n, s, o in todo]
            for future in tqdm(as_completed(futures), total=len(futures), desc="cells", unit="cell"):
                future.result()
    done = [job for job in jobs if paths[job].exists()]
    if not done:
        print("no finished cells yet")
        return 0
    records = [r for job in done for r in ev.load_cell(paths[job])]
    config = {"policies": args.policies, "ns": ns, "runs": args.runs, "seeds": args.seeds,
              "object_sets": args.object_sets, "complete": len(done) == len(jobs),
              "command": " ".join(["shelf-evaluate", *(sys.argv[1:] if argv is None else argv)])}
    rows = ev.write_results(args.out, records, config)
    for object_set in args.object_sets:
        ev.plot_metrics(rows, args.out / f"sr_ae_mae_{object_set}.png", object_set,
                        title=f"ShelfSort-v0, {object_set} objects, {args.runs} runs x {args.seeds} seeds")
    if len(args.object_sets) > 1:
        ev.plot_metrics(rows, args.out / "train_vs_test.png", None, title="training vs test (YCB) objects")
    for row in rows:
        print(f"{row['policy']:>8s} {row['object_set']:>5s} N={row['num_objects']:2d}  "
              f"SR {row['sr_mean']:5.1f} ± {row['sr_std']:4.1f}  AE {row['ae_mean']:.2f}  mAE {row['mae_mean']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
