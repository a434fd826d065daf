"""A model soup: one PixelDoubleDQN checkpoint whose Q-network weights are the mean of several checkpoints'.

Distilled P+S models all start from the same RL-trained weights (`distill --init`) and are trained by the same
recipe on nested slices of the dataset, so their weights may lie in one basin, where their mean is a model of its
own rather than noise; averaging one run's last epochs (`distill --average-last`) already added about 2 points
(docs/experiments/distill-scaling.md). This averages across runs. The ingredients must share one layout
(observation and action spaces, map layout, parameter names and shapes); the soup keeps the first one's settings
(its optimiser state too: a soup is for playing, not for resuming training from) and writes ``<out>.soup.json``
beside it naming the ingredients and their sha256.

    python research/model_soup.py A.zip B.zip [C.zip ...] --out runs/soup.zip \
        [--val-shards s00:55,s01:50 --teacher-radius 2 --teacher-temperature 1]

With ``--val-shards``, it also prints (JSON lines) each ingredient's and the soup's distillation loss on the
validation states of those shards (`shelf_env.training.distill`'s split, at the loss options given), states that
none of the ingredients trained on when they are the validation states of the largest one's run.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import sys
from collections.abc import Sequence
from typing import Any

import torch as th

from shelf_env.files import write_json_atomically


def report_path(out: str | pathlib.Path) -> pathlib.Path:
    """Where the soup's list of ingredients is written: ``NAME.soup.json`` beside it (as distill's reports)."""
    return pathlib.Path(out).with_suffix(".soup.json")


def _layout(model: Any) -> tuple[Any, ...]:
    return (model.observation_space, model.action_space, model.policy_kwargs.get("maps"),
            {k: tuple(v.shape) for k, v in model.q_net.state_dict().items()})


def mean_state(states: Sequence[dict[str, th.Tensor]]) -> dict[str, th.Tensor]:
    """The entrywise mean of several state dicts with one set of names and shapes (floating tensors; any other
    tensor, e.g. a counter, must be equal in all of them and is kept)."""
    mean = {}
    for name, first in states[0].items():
        tensors = [s[name] for s in states]
        if first.is_floating_point():
            mean[name] = th.stack([t.to(th.float64) for t in tensors]).mean(0).to(first.dtype)
        elif all(th.equal(first, t) for t in tensors[1:]):
            mean[name] = first.clone()
        else:
            raise ValueError(f"the ingredients' {name!r} differ and cannot be averaged")
    return mean


def soup(paths: Sequence[str | pathlib.Path], out: str | pathlib.Path) -> dict[str, Any]:
    """Save the mean of the checkpoints ``paths`` (at least two, one layout) as ``out``; returns its report."""
    from sb3_pixeldqn import PixelDoubleDQN

    files, out = [pathlib.Path(p) for p in paths], pathlib.Path(out)
    if out.suffix != ".zip":
        raise ValueError(f"the soup is an SB3 zip: --out must end in .zip, got {str(out)!r}")
    if len(files) < 2:
        raise ValueError(f"a soup needs at least two checkpoints, got {len(files)}")
    missing = [str(p) for p in files if not p.is_file()]
    if missing:
        raise ValueError(f"no such checkpoint: {', '.join(missing)}")
    models = [PixelDoubleDQN.load(p, device="cpu") for p in files]
    for path, model in zip(files[1:], models[1:]):
        if _layout(model) != _layout(models[0]):
            raise ValueError(f"{path} does not share {files[0]}'s layout (spaces, maps, parameter shapes)")
    base = models[0]
    base.q_net.load_state_dict(mean_state([m.q_net.state_dict() for m in models]))
    base.q_net_target.load_state_dict(base.q_net.state_dict())
    report = {"out": str(out), "ingredients": [{"path": str(p), "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
                                               for p in files]}
    base.save(out)  # atomic, as every PixelDoubleDQN save
    write_json_atomically(report_path(out), report)
    return report


def validation_losses(paths: Sequence[str | pathlib.Path], data: pathlib.Path, max_shards: str,
                      loss: Any, val_fraction: float = 0.2) -> dict[str, dict[str, float]]:
    """Each checkpoint's `sb3_pixeldqn.distill.evaluate` (loss terms, invalid and teacher choices) on the
    validation states of ``max_shards`` of ``data``, split as `shelf_env.training.distill` splits them."""
    from sb3_pixeldqn import PixelDoubleDQN
    from sb3_pixeldqn.distill import evaluate
    from shelf_env.privileged import dataset
    from shelf_env.training.distill import split_states

    val = split_states(dataset.select_shards(dataset.load_dataset(data), max_shards), val_fraction)[1]
    if val is None:
        raise ValueError(f"{max_shards} at val_fraction {val_fraction} leaves no validation states")
    return {str(p): evaluate(PixelDoubleDQN.load(p, device="cpu").policy, val, loss) for p in paths}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python research/model_soup.py", description=__doc__.split("\n")[0])
    p.add_argument("checkpoints", nargs="+", type=pathlib.Path, help="PixelDoubleDQN zips of one layout")
    p.add_argument("--out", type=pathlib.Path, required=True, help="the soup (an SB3 zip)")
    p.add_argument("--val-shards", default=None, help="also print every model's loss on the validation states of "
                   "these shards of --data (distill's --max-shards syntax)")
    p.add_argument("--data", type=pathlib.Path, default=pathlib.Path("data/teacher"), help="the dataset folder")
    p.add_argument("--val-fraction", type=float, default=0.2, help="the share of each series' scenes that are "
                   "validation (distill's --val-fraction)")
    p.add_argument("--teacher-radius", type=int, default=0, help="the validation loss's teacher radius")
    p.add_argument("--teacher-temperature", type=float, default=0.0, help="the validation loss's teacher temperature")
    args = p.parse_args(argv)
    try:
        soup(args.checkpoints, args.out)
        if args.val_shards is not None:
            from sb3_pixeldqn.distill import LossOptions

            loss = LossOptions(teacher_radius=args.teacher_radius, teacher_temperature=args.teacher_temperature)
            losses = validation_losses([*args.checkpoints, args.out], args.data, args.val_shards, loss,
                                       args.val_fraction)
            for path, row in losses.items():
                print(json.dumps({"model": path, **{k: round(v, 4) for k, v in row.items()}}), flush=True)
    except ValueError as err:
        print(f"model_soup: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
