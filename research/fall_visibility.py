"""Is the fall visible? The same fall model on the camera's heightmap and on an unoccluded top-down one.

docs/experiments/fall-visibility.md. The teacher dataset stores the camera observation of each state; the
top-down one (`shelf_env.privileged.topdown`) has to be read from the simulator, so each chosen state is
replayed from its scene's reset seed and executed actions:

- `replay` (resumable, one ``sNN_NNNNN.npz`` per dataset shard in ``--out``, written atomically; ``--part
  k/K`` for K processes): per chosen state of the shard, its top-down observation and whether the
  replayed camera observation equals the stored one (a replay is bit-identical only on the machine that
  collected the shard; a state that differs is left out of both models).
- `compare`: trains `research.fall_risk.fit_fall_risk` twice on the same states and pick labels (the
  stored camera observations, then the top-down ones), and reports each model's held-out AUC and the
  offline check of `research.fall_risk.penalty_report` (the checkpoint's choice among the labelled picks,
  its Q-values read from the camera observation, under a mask or a soft penalty of each model's risk).

The states: the fall model's split (`research.fall_risk.load_splits`: ``--max-shards``, ``--val-fraction``),
the first ``--max-states`` training states and every held-out state.
"""

from __future__ import annotations

import argparse
import functools
import json
import pathlib
import sys
import time
from typing import Any

import numpy as np
import torch as th

from research import fall_risk
from shelf_env.baselines.heuristics import object_blobs
from shelf_env.files import write_atomically, write_json_atomically
from shelf_env.privileged import dataset
from shelf_env.privileged.topdown import topdown_observation


def chosen_states(data: pathlib.Path, val_fraction: float, max_shards: str | None,
                  max_states: int | None) -> tuple[list[dataset.Shard], np.ndarray, np.ndarray]:
    """The shards and the (sorted) global state indices of the training states and the held-out states the
    fall model's split gives (`research.fall_risk.load_splits`'s choice)."""
    from shelf_env.training.distill import split_by_scene

    shards = dataset.select_shards(dataset.load_dataset(data), max_shards)
    train, val = split_by_scene(shards, val_fraction)
    if not val:
        raise ValueError(f"{data}: {len(shards)} shards leave no held-out scene at val_fraction {val_fraction}")
    return shards, np.array(train[:max_states] if max_states is not None else train), np.array(val)


def replay_shard(shard: dataset.Shard, wanted: np.ndarray) -> dict[str, np.ndarray]:
    """Replay the scenes of ``shard`` that hold a state of ``wanted`` (indices within the shard) and, at each,
    read the top-down observation and whether the camera's equals the stored one. One env step per state:
    each scene is replayed once, forward."""
    env = dataset.replay_env(shard)
    a = shard.arrays
    top = np.zeros((len(wanted), *a["obs"].shape[1:]), np.uint8)
    match = np.zeros(len(wanted), bool)
    where = {int(s): k for k, s in enumerate(wanted)}
    try:
        for i, ep in enumerate(shard.meta["episodes"]):
            states = [int(s) for s in np.flatnonzero(a["state_episode"] == i) if int(s) in where]
            if not states:
                continue
            env.unwrapped.set_num_objects(ep["num_objects"])  # type: ignore[attr-defined]
            obs, _ = env.reset(seed=ep["reset_seed"])
            at = {int(a["state_step"][s]): s for s in states}
            for t in range(max(at) + 1):
                if t in at:
                    k = where[at[t]]
                    match[k] = np.array_equal(obs, a["obs"][at[t]])
                    top[k] = topdown_observation(env)
                if t < max(at):
                    obs, _, _, _, _ = env.step(int(ep["actions"][t]))
    finally:
        env.close()
    return {"state": np.asarray(wanted, np.int64), "topdown": top, "match": match}


def replay(data: pathlib.Path, out: pathlib.Path, val_fraction: float, max_shards: str | None,
           max_states: int | None, part: int = 0, parts: int = 1) -> dict[str, int]:
    """Write ``out/<shard name>`` for each shard (every ``parts``-th from ``part``) that holds a chosen state
    and has none yet (see the module docstring). Returns counts of shards written, skipped, and states."""
    if not 0 <= part < parts:
        raise ValueError(f"need 0 <= part < parts, got part {part} of {parts}")
    shards, train, val = chosen_states(data, val_fraction, max_shards, max_states)
    chosen = np.concatenate([train, val])
    out.mkdir(parents=True, exist_ok=True)
    counts = {"written": 0, "skipped": 0, "states": 0}
    first = 0
    for k, shard in enumerate(shards):
        wanted = chosen[(chosen >= first) & (chosen < first + shard.num_states)] - first
        first += shard.num_states
        target = out / shard.path.name
        if not len(wanted) or k % parts != part:
            continue
        if target.exists():
            counts["skipped"] += 1
            continue
        t0 = time.time()
        arrays = replay_shard(shard, wanted)
        write_atomically(target, functools.partial(_savez, arrays=arrays))
        counts["written"] += 1
        counts["states"] += len(wanted)
        print(f"{shard.path.name} {len(wanted)} states, {int(arrays['match'].sum())} match, "
              f"{time.time() - t0:.1f} s", flush=True)
    return counts


def _savez(path: pathlib.Path, arrays: dict[str, np.ndarray]) -> None:
    with open(path, "wb") as f:  # a file object: np.savez would add ".npz" to a path
        np.savez_compressed(f, **arrays)  # type: ignore[arg-type]


def topdown_split(split: fall_risk.Split, index: np.ndarray, shards: list[dataset.Shard],
                  folder: pathlib.Path) -> tuple[fall_risk.Split, fall_risk.Split]:
    """``split`` (whose observation ``j`` is global state ``index[j]``) restricted to the states whose replay
    matched, once with its camera observations and once with the top-down ones from ``folder``. A shard
    with a chosen state and no replay file is a `ValueError` naming it."""
    offsets = np.cumsum([0] + [s.num_states for s in shards])
    top = np.zeros(split.obs.shape, np.uint8)
    match = np.zeros(len(index), bool)
    for k, shard in enumerate(shards):
        mine = np.flatnonzero((index >= offsets[k]) & (index < offsets[k + 1]))
        if not len(mine):
            continue
        path = folder / shard.path.name
        if not path.exists():
            raise ValueError(f"no top-down replay of {shard.path.name} in {folder} (python -m "
                             "research.fall_visibility replay writes it)")
        with np.load(path) as f:
            rows = {int(s): j for j, s in enumerate(f["state"])}
            local = index[mine] - offsets[k]
            if any(int(s) not in rows for s in local):
                raise ValueError(f"{path}: the replay lacks states of this split (another --max-states?)")
            pick = [rows[int(s)] for s in local]
            top[mine], match[mine] = f["topdown"][pick], f["match"][pick]
    keep = np.flatnonzero(match)
    return subset(split, keep), subset(split, keep, th.as_tensor(top))


def subset(split: fall_risk.Split, keep: np.ndarray, obs: th.Tensor | None = None) -> fall_risk.Split:
    """The states ``keep`` of ``split`` (rows of its observations, or of ``obs`` in their place) and their labels."""
    new = np.full(len(split.obs), -1, np.int64)
    new[keep] = np.arange(len(keep))
    state = new[split.state.numpy()]
    labels = state >= 0
    lab = th.as_tensor(labels)
    return fall_risk.Split((split.obs if obs is None else obs)[th.as_tensor(keep)], th.as_tensor(state[labels]),
                           split.cell[lab], split.label[lab],
                           None if split.objects is None else split.objects[keep],
                           None if split.sorted_change is None else split.sorted_change[labels])


def compare(data: pathlib.Path, folder: pathlib.Path, checkpoint: str, out: pathlib.Path, val_fraction: float,
            max_shards: str | None, max_states: int | None, epochs: int = 8, models: pathlib.Path | None = None,
            init: str | None = "checkpoint") -> dict[str, Any]:
    """Train the camera and the top-down fall model on the same replayed states (see the module docstring) and
    write their report to ``out`` (JSON; with ``models``, each model too, ``<view>.fall_risk.pt``). Both start
    from ``init``'s pick FCN: ``"checkpoint"`` (the default) the checkpoint's, None from scratch."""
    shards, train_index, val_index = chosen_states(data, val_fraction, max_shards, max_states)
    train, val = fall_risk.teacher_split(shards, train_index), fall_risk.teacher_split(shards, val_index)
    train_cam, train_top = topdown_split(train, train_index, shards, folder)
    val_cam, val_top = topdown_split(val, val_index, shards, folder)
    values, groups = fall_risk.pick_values(checkpoint, val_cam)  # the Q-values read from the camera image
    labels = val_cam.label.numpy()
    report: dict[str, Any] = {
        "checkpoint": checkpoint, "init": checkpoint if init == "checkpoint" else init, "max_shards": max_shards,
        "max_states": max_states, "val_fraction": val_fraction,
        "train_states": len(train_cam.obs), "train_dropped": len(train.obs) - len(train_cam.obs),
        "train_labels": len(train_cam.label), "val_states": len(val_cam.obs),
        "val_dropped": len(val.obs) - len(val_cam.obs), "val_labels": len(labels),
        "val_invalid": float(labels.mean()), "views": {}}
    scored = {}
    for view, tr, va in (("camera", train_cam, val_cam), ("topdown", train_top, val_top)):
        model, history, best = fall_risk.fit_fall_risk(tr, va, report["init"], epochs)
        p = fall_risk.scores(model, va)
        model.threshold = fall_risk.pick_threshold(labels, p)
        scored[view] = p
        report["views"][view] = {"val_auc": fall_risk.auc(labels, p), "best_epoch": best, "history": history,
                                 **fall_risk.threshold_report(labels, p, model.threshold)}
        if models is not None:
            model.save(models / f"{view}.fall_risk.pt", {"view": view, "obs_shape": list(tr.obs.shape[1:]),
                                                          **report["views"][view]})
    assert val_cam.sorted_change is not None
    report["offline"] = fall_risk.penalty_report(labels, val_cam.sorted_change, values, scored, groups)
    report["delta_auc"] = report["views"]["topdown"]["val_auc"] - report["views"]["camera"]["val_auc"]
    write_json_atomically(out, report)
    return report


def neighbour_agreement(split: fall_risk.Split, distances: tuple[int, ...] = (1, 2, 3)) -> dict[str, Any]:
    """How well a pick's outcome is predicted by the outcome of the nearest other labelled pick of the same object
    (the same blob, `object_blobs`) in the same state: per distance ``d`` (cells, Chebyshev), over the
    labels whose nearest such neighbour is at most ``d`` away, their number and invalid share, the share of
    (label, nearest neighbour) pairs that differ, and the AUC of the neighbours' mean outcome as a predictor."""
    labels, cells, states = split.label.numpy(), split.cell.numpy(), split.state.numpy()
    cols = split.obs.shape[-1]
    nearest = np.full(len(labels), np.inf)
    predicted = np.full(len(labels), np.nan)
    differ = np.full(len(labels), np.nan)
    for index in fall_risk.state_groups(states):
        blob = object_blobs(split.obs[int(states[index[0]])].numpy()).reshape(-1)
        r, c, b = cells[index] // cols, cells[index] % cols, blob[cells[index]]
        dist = np.maximum(np.abs(r[:, None] - r[None]), np.abs(c[:, None] - c[None])).astype(float)
        dist[(b[:, None] != b[None]) | (b[:, None] < 0)] = np.inf  # another object, or no object
        np.fill_diagonal(dist, np.inf)
        near = dist.min(axis=1)
        for i in np.flatnonzero(np.isfinite(near)):
            mates = labels[index][dist[i] == near[i]]
            nearest[index[i]], predicted[index[i]] = near[i], mates.mean()
            differ[index[i]] = (mates != labels[index[i]]).mean()
    out: dict[str, Any] = {"labels": len(labels), "states": len(split.obs), "by_distance": {}}
    for d in distances:
        sel = nearest <= d
        out["by_distance"][str(d)] = {
            "labels": int(sel.sum()), "invalid": float(labels[sel].mean()) if sel.any() else float("nan"),
            "differ": float(differ[sel].mean()) if sel.any() else float("nan"),
            "auc": fall_risk.auc(labels[sel], predicted[sel]) if sel.any() else float("nan")}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.fall_visibility", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    n = sub.add_parser("neighbours", help="how well the nearest labelled pick of the same object predicts a pick")
    n.add_argument("--data", type=pathlib.Path, required=True)
    n.add_argument("--max-shards", default=None)
    n.add_argument("--val-fraction", type=float, default=0.2)
    n.add_argument("--out", type=pathlib.Path, required=True, help="the report (JSON)")
    for name, text in (("replay", "the top-down observations of the chosen states (resumable)"),
                       ("compare", "the camera and the top-down fall model on the same states")):
        p = sub.add_parser(name, help=text)
        p.add_argument("--data", type=pathlib.Path, required=True)
        p.add_argument("--replays", type=pathlib.Path, required=True, help="the folder of top-down replays")
        p.add_argument("--max-shards", default=None)
        p.add_argument("--max-states", type=int, default=None)
        p.add_argument("--val-fraction", type=float, default=0.2)
        if name == "replay":
            p.add_argument("--part", default="0/1", help="k/K: every K-th shard from the k-th (K processes)")
        else:
            p.add_argument("--checkpoint", required=True, help="the P+S zip: the models' start, the Q-values")
            p.add_argument("--epochs", type=int, default=8)
            p.add_argument("--init", default="checkpoint",
                           help="the zip whose pick FCN starts both models ('checkpoint': --checkpoint; 'none')")
            p.add_argument("--out", type=pathlib.Path, required=True, help="the report (JSON)")
            p.add_argument("--models", type=pathlib.Path, default=None, help="also save both models here")
    args = parser.parse_args(argv)
    try:
        if args.command == "neighbours":
            _, val = fall_risk.load_splits(args.data, args.val_fraction, args.max_shards)
            result = {"max_shards": args.max_shards, "val_fraction": args.val_fraction, **neighbour_agreement(val)}
            write_json_atomically(args.out, result)
            print(json.dumps(result))
        elif args.command == "replay":
            try:
                part, parts = (int(v) for v in args.part.split("/"))
            except ValueError:
                raise ValueError(f"--part must be k/K, got {args.part!r}") from None
            print(json.dumps(replay(args.data, args.replays, args.val_fraction, args.max_shards, args.max_states,
                                    part, parts)))
        else:
            if args.models is not None:
                args.models.mkdir(parents=True, exist_ok=True)
            report = compare(args.data, args.replays, args.checkpoint, args.out, args.val_fraction, args.max_shards,
                             args.max_states, args.epochs, args.models,
                             None if args.init == "none" else args.init)
            print(json.dumps({k: v for k, v in report.items() if k not in ("views", "offline")} |
                             {v: r["val_auc"] for v, r in report["views"].items()}))
    except ValueError as err:
        print(f"python -m research.fall_visibility {args.command}: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
