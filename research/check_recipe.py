"""Check a checkpoint against issue 9's N = 3 criteria on held-out scenes, beside H-d on the same scenes.

    python research/check_recipe.py results/learning/recipe_n3.zip --scenes 50 \\
        --out results/learning/recipe_n3_check.json

The checkpoint acts greedily with the env's action masks (as it was trained) on ``--scenes``
scenes of training objects and of YCB objects at N = 3 from evaluation seed
`shelf_env.evaluation.protocol.HELDOUT_SEED`; H-d plays the same scenes. Criteria: >= 90 % sorted on
training objects, >= 80 % on YCB, < 5 % unchanged-observation actions, actions per success
<= 1.5x H-d's (per object set). Cells run in parallel worker processes (one torch thread each) and
are cached under ``<out folder>/cells/``, so an interrupted check resumes.
"""

from __future__ import annotations

import argparse
import os
import pathlib
from concurrent.futures import ProcessPoolExecutor

from shelf_env.evaluation import protocol as ev
from shelf_env.files import write_json_atomically
from shelf_env.processes import exit_with_parent

N = 3


def _cell(policy: str, object_set: str, scenes: int, out: pathlib.Path) -> list[ev.EpisodeRecord]:
    import torch

    torch.set_num_threads(1)
    return ev.cached_cell(out, policy, N, ev.HELDOUT_SEED, scenes, object_set)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("checkpoint")
    p.add_argument("--scenes", type=int, default=50)
    p.add_argument("--out", type=pathlib.Path, required=True)
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args(argv)
    ev.check_policy(args.checkpoint)
    jobs = {(policy, oset): (policy, oset, args.scenes, args.out.parent)
            for policy in (args.checkpoint, "h-d") for oset in ("train", "ycb")}
    with ProcessPoolExecutor(args.workers, initializer=exit_with_parent, initargs=(os.getpid(),)) as pool:
        futures = {key: pool.submit(_cell, *job) for key, job in jobs.items()}
        results = {key: ev.episode_summary(f.result()) for key, f in futures.items()}
    learned = {oset: results[(args.checkpoint, oset)] for oset in ("train", "ycb")}
    hd = {oset: results[("h-d", oset)] for oset in ("train", "ycb")}
    criteria = {
        "sr_train >= 90": learned["train"]["sr"] >= 90,
        "sr_ycb >= 80": learned["ycb"]["sr"] >= 80,
        "noop_share < 5 % (both sets)": max(learned[s]["noop_share"] for s in learned) < 0.05,
        "actions/success <= 1.5 x H-d (both sets)": all(
            learned[s]["actions_per_success"] <= 1.5 * hd[s]["actions_per_success"] for s in learned),
    }
    report = {"checkpoint": args.checkpoint, "num_objects": N, "heldout_seed": ev.HELDOUT_SEED,
              "scenes": args.scenes, "learned": learned, "h-d": hd, "criteria": criteria,
              "passed": all(criteria.values())}
    write_json_atomically(args.out, report)
    for oset in ("train", "ycb"):
        a, b = learned[oset], hd[oset]
        print(f"{oset:5s}: learned {a['sorted']}/{a['scenes']} sorted, {a['actions_per_success']:.2f} actions/success, "
              f"{100 * a['noop_share']:.1f} % unchanged, {a['fell']} falls | H-d {b['sorted']}/{b['scenes']}, "
              f"{b['actions_per_success']:.2f} actions/success")
    for name, ok in criteria.items():
        print(f"  {'PASS' if ok else 'FAIL'}  {name}")
    return report


if __name__ == "__main__":
    main()
