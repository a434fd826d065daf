"""Evaluate policies on ShelfSort-v0 with the paper's protocol (§V) and plot Fig. 10 / Fig. 12.

    shelf-evaluate --policies h-d h-a random --ns 3-14 --runs 20 --seeds 2 \\
        --object-sets ycb --out results/baselines --workers 2

Policies: ``h-d``, ``h-a``, ``random``, the privileged diagnostics ``h-d-lookahead`` and
``h-a-lookahead`` (`shelf_env.privileged.lookahead`) or a PixelDoubleDQN checkpoint zip (its P+S or S layout
decides the env's primitives). The seeds are 0..S-1, the held-out scenes learning claims use; ``--first-seed F``
plays F..F+S-1 instead (e.g. the validation scenes of seed 2000, where a choice between models may look).
Every (policy, object set, N, seed) cell runs in a worker process
and is written to ``<out>/cells/`` as soon as it finishes; running the same command again skips
the cells already on disk, so an interrupted evaluation resumes. A checkpoint's cells are named
by its file stem, or by LABEL given as ``LABEL=PATH`` (``--policies mine=runs/a/model.zip``), and
``<out>/cells/<label>.sha256`` records which file they came from: another file of that label (a retrained
model shipped again) is refused instead of inheriting them.
``--reuse-cells FOLDER`` copies the grid's cells that another folder, evaluated under the same
conditions (and from the same checkpoint files), already holds. Episodes are bit-identical on one
machine, not across machines: PyBullet's floating point differs between CPUs (5 of H-d's 30
episodes at N = 8, seed 0, ended differently on two machines: SR 36.7 vs 40.0), so cells run on
another machine are the same scenes but not exactly the same episodes. Each episode record names
the machine that played it (``machine``), ``results.json`` counts episodes per machine and the
command prints a note when they come from more than one. At the end (or with
``--summarize-only``) it writes ``results.csv``, ``results.json`` (with this configuration) and
``sr_ae_mae_<set>.png`` (Fig. 10), plus ``train_vs_test.png`` (Fig. 12) when both object sets
were evaluated.

Backends: ``--backend local`` (default) runs the cells in ``--workers`` local processes;
``--backend ray`` runs them as Ray tasks (the ``ray`` extra), on a local Ray instance with
``--workers`` CPUs or, with ``--ray-address host:port`` (or ``ray://host:port``, ``auto``), on an
existing cluster whose nodes have this project installed. The driver writes each cell as it
returns, so both backends leave the same resumable files, and the same records: episodes are
history-free (`shelf_env.env`), so a cell's records depend only on (policy, N, seed, runs).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import multiprocessing as mp
import os
import pathlib
import socket
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from tqdm import tqdm

from shelf_env import policies
from shelf_env.evaluation import protocol as ev
from shelf_env.files import copy_atomically, write_json_atomically
from shelf_env.processes import worker_initializer

#: A cell: (policy, N, seed, object set).
Job = tuple[str, int, int, str]


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


def json_object(text: str) -> dict:
    """A JSON object from the command line."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as err:
        raise argparse.ArgumentTypeError(f"not JSON: {err}") from err
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"expected a JSON object like '{{\"dropout\": 0.1}}', got {text}")
    return value


def closed_loop_fields(changes: dict) -> dict:
    """Every field of the closed loop's watch (`shelf_env.conditions.closed_loop.DragWatch`) with ``changes`` made:
    what a folder's ``conditions.json`` records, so that a later change of the defaults cannot
    resume a folder under another watch."""
    from shelf_env.conditions.closed_loop import DragWatch

    watch = DragWatch.from_any(changes)
    assert watch is not None  # a dict always gives a watch
    return dataclasses.asdict(watch)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="shelf-evaluate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--policies", nargs="+", required=True, help="h-d, h-a, random, h-d-lookahead, h-a-lookahead "
                                                                 "or checkpoint .zip paths; any of them+loop-breaker: "
                                                                 "played under sb3_pixeldqn's LoopBreaker; LABEL=... "
                                                                 "names its results LABEL (default: the file stem)")
    p.add_argument("--ns", type=parse_ns, default=list(range(3, 15)), help="e.g. 3-14 or 3,5,8")
    p.add_argument("--runs", type=int, default=100, help="episodes per (policy, N, seed) (paper: 100)")
    p.add_argument("--seeds", type=int, default=5, help="number of seeds, 0..S-1 (paper: 5)")
    p.add_argument("--first-seed", type=int, default=0, metavar="F",
                   help="play seeds F..F+S-1 instead: other scenes, e.g. validation scenes for choosing a model "
                        "(shelf_env.evaluation.falls.VALIDATION_SEED) that the held-out 0..S-1 never serve")
    p.add_argument("--object-sets", nargs="+", choices=["ycb", "train"], default=["ycb"],
                   help="unseen YCB objects (the paper's test) and/or the training objects (Fig. 12)")
    p.add_argument("--out", type=pathlib.Path, required=True,
                   help="the evaluation folder: cells/, results.csv, results.json, plots; resumed when it has cells")
    p.add_argument("--workers", type=int, default=2, help="cells evaluated at once (one process or Ray task each)")
    p.add_argument("--summarize-only", action="store_true",
                   help="only aggregate the cells already on disk (a checkpoint need not be on this machine: its "
                        "cells are summarized, their file digest unchecked)")
    p.add_argument("--reuse-cells", type=pathlib.Path, default=None, metavar="FOLDER",
                   help="copy this grid's cells from another evaluation folder made under the same conditions "
                        "(and, for checkpoints, from the same file) instead of running them again")
    p.add_argument("--perception-noise", type=json_object, default=None, metavar="JSON",
                   help='evaluate under perception noise, e.g. \'{"dropout": 0.1, "class_flip": 0.05}\'')
    p.add_argument("--closed-loop", nargs="?", const={}, type=json_object, default=None, metavar="JSON",
                   help="evaluate with closed-loop primitives (shelf_env.conditions.closed_loop.DragWatch); "
                        "an optional JSON "
                        'object changes the watch\'s fields, e.g. \'{"sustain": 2, "threshold": 0.5}\'')
    p.add_argument("--safe-picks", action="store_true",
                   help="evaluate with the env's safe_picks: every policy picks only objects whose carry out "
                        "of the opening clears the other visible objects (shelf_env.conditions.safe_picks)")
    p.add_argument("--physics", default=None, metavar="NAME",
                   help='"reference" to evaluate on the physics of results before 2026-11-23 '
                        '(default: the env\'s, "fast"; shelf_env.world.cabinet.PHYSICS)')
    p.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="local worker processes (default) or Ray tasks (the ray extra)")
    p.add_argument("--ray-address", default=None,
                   help="an existing Ray cluster (host:port, ray://host:port or auto); default: a local Ray "
                        "instance with --workers CPUs")
    return p.parse_args(argv)


def _run_cell(policy: str, n: int, seed: int, runs: int, object_set: str, path: str, parent_pid: int,
              conditions: dict | None = None) -> bool:
    """Run one cell and write it; True if written. A worker whose parent died meanwhile (the
    evaluation was killed, maybe to change the code) discards its cell instead of writing it."""
    import torch

    torch.set_num_threads(1)
    records = ev.evaluate_cell(policy, n, seed, runs, object_set, conditions=conditions)
    if os.getppid() != parent_pid:
        return False
    ev.save_cell(pathlib.Path(path), records)
    return True


def run_local(todo: list[Job], paths: dict[Job, pathlib.Path], runs: int, workers: int,
              conditions: dict | None = None) -> None:
    """Every cell of ``todo`` in a worker process; each worker writes its cell when done."""
    ctx = mp.get_context("spawn")
    # a spawned worker imports the modules that registered the policies' wrappers (an experiment's)
    # ... and ends when this process does (killed, its pool's shutdown never runs)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=worker_initializer,
                             initargs=(os.getpid(), policies.import_modules, policies.registering_modules())) as pool:
        futures = [pool.submit(_run_cell, p, n, s, runs, o, str(paths[(p, n, s, o)]), os.getpid(), conditions)
                   for p, n, s, o in todo]
        for future in tqdm(as_completed(futures), total=len(futures), desc="cells", unit="cell"):
            future.result()


def check_ray_address(address: str | None, timeout: float = 5.0) -> None:
    """A `ValueError` naming ``address`` when no Ray cluster answers there (Ray itself retries for minutes)."""
    if address in (None, "auto", "local"):
        return
    assert address is not None
    host_port = address.removeprefix("ray://").rsplit(":", 1)
    if len(host_port) != 2 or not host_port[1].isdigit():
        raise ValueError(f"--ray-address must be host:port, ray://host:port or auto, got {address!r}")
    try:
        socket.create_connection((host_port[0], int(host_port[1])), timeout=timeout).close()
    except OSError as err:
        raise ValueError(f"cannot reach a Ray cluster at {address}: {err}") from err


def _ray_cell(policy: str, checkpoint: bytes | None, n: int, seed: int, runs: int,
              object_set: str, conditions: dict | None = None) -> list[ev.EpisodeRecord]:
    """One cell on a Ray worker. A checkpoint travels as bytes (a cluster's nodes need not share the
    driver's disk); the policy keeps its label (`policies.relabelled_file`), so the records are the same."""
    import tempfile

    import torch

    torch.set_num_threads(1)
    if checkpoint is None:
        return ev.evaluate_cell(policy, n, seed, runs, object_set, conditions=conditions)
    with tempfile.TemporaryDirectory() as tmp:
        local = pathlib.Path(tmp) / pathlib.Path(ev.policy_file(policy)).name
        local.write_bytes(checkpoint)
        return ev.evaluate_cell(policies.relabelled_file(policy, local), n, seed, runs, object_set,
                                conditions=conditions)


def run_ray(todo: list[Job], paths: dict[Job, pathlib.Path], runs: int, workers: int, address: str | None,
            conditions: dict | None = None) -> None:
    """Every cell of ``todo`` as a Ray task (one CPU each); the driver writes each cell as it returns."""
    import ray

    try:
        if address in (None, "local"):
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
        else:
            ray.init(address=address, log_to_driver=False, ignore_reinit_error=True)
    except Exception as err:  # noqa: BLE001  (Ray raises several types for an unusable cluster)
        raise ValueError(f"cannot start or reach Ray ({address or 'local'}): {err}") from err
    cell = ray.remote(num_cpus=1)(_ray_cell)
    blobs: dict[str, Any] = {p: ray.put(pathlib.Path(ev.policy_file(p)).read_bytes())
                             for p in {job[0] for job in todo} if not ev.is_named(p)}
    pending = {cell.remote(p, blobs.get(p), n, s, runs, o, conditions): (p, n, s, o) for p, n, s, o in todo}
    with tqdm(total=len(pending), desc="cells (ray)", unit="cell") as bar:
        while pending:
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            ev.save_cell(paths[pending.pop(ref)], ray.get(ref))
            bar.update()


def check_reuse(source: pathlib.Path, policies: list[str], conditions: dict) -> None:
    """``--reuse-cells``: ``source`` must be an evaluation folder made under the same conditions
    whose checkpoint cells (if any) came from the same files (`evaluation.check_cell_owner`)."""
    if not (source / "cells").is_dir():
        raise ValueError(f"--reuse-cells {source} has no cells/ folder")
    before = ev.folder_conditions(source)
    if before != conditions:
        raise ValueError(f"--reuse-cells {source} holds cells evaluated under conditions {before or 'none'}, "
                         f"not {conditions or 'none'}")
    ev.check_cell_owner(source, policies)


def reuse_cells(source: pathlib.Path, todo: list[Job], paths: dict[Job, pathlib.Path]) -> int:
    """Copy the cells of ``todo`` that ``source`` (checked by `check_reuse`) holds; returns how many.

    A cell depends only on (policy, N, seed, runs) and the conditions (episodes are history-free),
    so such a folder holds the episodes this evaluation would run, bit for bit if it was run on the
    same machine (see the module docstring). A checkpoint's cells are taken only where ``source``
    recorded which file they came from."""
    copied = 0
    for job in todo:
        cell = source / "cells" / paths[job].name
        if cell.exists() and (ev.is_named(job[0]) or ev.fingerprint_path(source, job[0]).exists()):
            copy_atomically(cell, paths[job])
            copied += 1
    return copied


def check_out_conditions(out: pathlib.Path, conditions: dict) -> None:
    """One output folder holds cells of one set of conditions: a folder made under other
    conditions is refused (its cells would be mixed with these)."""
    if (out / "conditions.json").exists():
        before = ev.folder_conditions(out)
        if before != conditions:
            raise ValueError(f"{out} holds cells evaluated under conditions {before}, not {conditions}: "
                             "use another --out")
    elif (out / "cells").is_dir() and any((out / "cells").iterdir()) and conditions:
        raise ValueError(f"{out} holds cells evaluated without conditions: use another --out for {conditions}")


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    # --summarize-only reads cells, not checkpoints: a checkpoint not on this machine (a fresh clone holds the
    # committed cells, not the runs/ that made them) is summarized from its cells, its fingerprint unchecked
    absent = [p for p in args.policies if args.summarize_only and not ev.is_named(p)
              and not pathlib.Path(ev.policy_file(p)).is_file()]
    present = [p for p in args.policies if p not in absent]
    try:  # every bad input is reported before any episode runs, in one line
        for policy in present:
            ev.check_policy(policy)
        ns = ev.check_ns(args.ns)
        if args.runs < 1 or args.seeds < 1 or args.workers < 1:
            raise ValueError("--runs, --seeds and --workers must be >= 1")
        if args.first_seed < 0:
            raise ValueError(f"--first-seed must be >= 0, got {args.first_seed}")
        if args.backend == "ray":
            try:
                import ray  # noqa: F401
            except ImportError as err:
                raise ValueError("--backend ray needs Ray: pip install '.[ray]'") from err
            beside = [p for p in args.policies  # files other than the checkpoint itself
                      if set(ev.policy_files(p)) - {pathlib.Path(policies.policy_file(p))}]
            if beside:  # a Ray task gets the checkpoint's bytes only, not a wrapper's model beside it
                raise ValueError(f"--backend ray carries only the checkpoint, not the files its wrappers read; "
                                 f"run {beside} with the local backend")
            check_ray_address(args.ray_address)
        elif args.ray_address is not None:
            raise ValueError("--ray-address needs --backend ray")
        conditions = ev.check_conditions(
            {**({"perception_noise": args.perception_noise} if args.perception_noise is not None else {}),
             **({"closed_loop": closed_loop_fields(args.closed_loop)} if args.closed_loop is not None else {}),
             **({"safe_picks": True} if args.safe_picks else {}),
             **({"physics": args.physics} if args.physics is not None else {})})
        check_out_conditions(args.out, conditions)
        ev.check_cell_owner(args.out, present)
        if args.reuse_cells is not None and not args.summarize_only:
            check_reuse(args.reuse_cells, args.policies, conditions)
    except ValueError as err:
        print(f"shelf-evaluate: error: {err}", file=sys.stderr)
        return 2
    jobs = [
        (policy, n, seed, object_set)
        for n in ns for seed in range(args.first_seed, args.first_seed + args.seeds)
        for object_set in args.object_sets for policy in args.policies
    ]
    paths = {job: ev.cell_path(args.out, job[0], job[3], job[1], job[2], args.runs) for job in jobs}
    todo = [job for job in jobs if not paths[job].exists()]
    print(f"{len(jobs)} cells, {len(jobs) - len(todo)} already on disk, {len(todo)} to run", flush=True)
    if absent:
        print(f"note: {len(absent)} checkpoint(s) not on this machine, summarized from their cells (file digests "
              f"unchecked): {', '.join(absent)}", flush=True)
    if todo and not args.summarize_only:
        if conditions and not (args.out / "conditions.json").exists():
            write_json_atomically(args.out / "conditions.json", conditions)
        ev.check_cell_owner(args.out, [job[0] for job in todo], record=True)
        if args.reuse_cells is not None:
            copied = reuse_cells(args.reuse_cells, todo, paths)
            todo = [job for job in todo if not paths[job].exists()]
            print(f"{copied} cells copied from {args.reuse_cells}, {len(todo)} to run", flush=True)
        start = time.perf_counter()
        if args.backend == "ray":
            try:
                run_ray(todo, paths, args.runs, args.workers, args.ray_address, conditions)
            except ValueError as err:
                print(f"shelf-evaluate: error: {err}", file=sys.stderr)
                return 2
        else:
            run_local(todo, paths, args.runs, args.workers, conditions)
        print(f"{len(todo)} cells in {time.perf_counter() - start:.1f} s ({args.backend} backend)", flush=True)
    done = [job for job in jobs if paths[job].exists()]
    if not done:
        print("no finished cells yet")
        return 0
    records = [r for job in done for r in ev.load_cell(paths[job])]
    config = {"policies": args.policies, "ns": ns, "runs": args.runs, "seeds": args.seeds,
              **({"first_seed": args.first_seed} if args.first_seed else {}), "conditions": conditions,
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
    played_on = ev.machines(records)
    if len(played_on) > 1:
        print(f"note: these episodes were played on {len(played_on)} machines (results.json's machines); episodes "
              "are bit-identical on one machine, not across machines: " + "; ".join(
                  f"{name}: {count}" for name, count in played_on.items()), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
