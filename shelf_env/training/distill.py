"""Distil the teacher dataset into a P+S model's Q-maps (`sb3_pixeldqn.distill`), then fine-tune as usual.

    python -m shelf_env.training.distill --data data/teacher --init examples/pretrained/v1/p_s.zip \\
        --out runs/distilled.zip --epochs 10 [--max-states 10000]

The dataset's scenes are split by scene (every state of a held-out scene is held out): the last
``--val-fraction`` of each shard series' scenes, in shard order, are validation. The report starts with the
starting model on the validation states (epoch 0); each epoch then reports the training loss and,
on the validation states, the loss and ``invalid_choice``: how often the model's best
labelled action of a state is one that ended the episode invalid (the driving model's greedy
action is labelled in every state, so this includes its choice). ``--max-states`` takes the first
states of the training scenes only, for a scaling curve. Each batch's states are drawn through the
model's own augmentation (``model.augment``: the shipped P+S's mirror and class permutation, exact
symmetries of the cabinet) unless ``--no-augment``. The teacher term's margin ranges over every action
a state's mask allows (read from its observation), so that the teacher's action becomes the greedy
argmax, unless ``--teacher-over labelled`` (its labelled actions only); with ``--teacher-radius R`` the
teacher's action stands for the cells of its map within R cells (its object rather than one pixel), and
with ``--progress-radius R`` the lower action of a progress pair does;
the progress term ranks a state's valid actions by the change in sorted objects they made, unless
``--no-progress``. With ``--average-last K`` the saved weights are the mean of the weights after each of the
last K epochs (the report's ``averaged`` holds their validation); ``--last-out PATH`` also saves the last
epoch's own weights there, with their report, so that one run gives both models of a comparison. The report
records what reproduces the run (options, shards, ``seed``). The model is saved atomically (an SB3 zip that
`PixelDoubleDQN.load` and ``shelf-train --init-from`` take); the report goes beside it as JSON.

A run checkpoints after every epoch (``NAME.resume.pt`` beside the model, or ``--resume-file PATH``: the weights,
the optimiser's state, the running mean of ``--average-last``, the history so far) and, started again with the
same settings, goes on from the last finished epoch, to the same weights as a run that was never stopped (each
epoch's batch order and augmentation are drawn from ``seed`` + epoch). A checkpoint of other settings (other
shards, options or starting model) is refused by name. The checkpoint is removed once the model is saved. On 2
CPU cores a run over the whole dataset takes longer than a working session; commit the checkpoint
(``--resume-file`` inside the repository) to go on from it on another machine.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import functools
import hashlib
import json
import pathlib
import sys
import time
from typing import Any

import numpy as np
import torch as th
from torch.optim.swa_utils import AveragedModel

from sb3_pixeldqn.distill import DEFAULT_WEIGHTS, LabelledStates, LossOptions, distill, evaluate
from shelf_env.files import write_atomically, write_json_atomically
from shelf_env.privileged import dataset


def report_path(model: str | pathlib.Path) -> pathlib.Path:
    """Where the report of the model saved at ``model`` goes: beside it, ``NAME.distill.json``."""
    return pathlib.Path(model).with_suffix(".distill.json")


def resume_path(model: str | pathlib.Path) -> pathlib.Path:
    """Where a run saving ``model`` checkpoints its epochs by default: beside it, ``NAME.resume.pt``."""
    return pathlib.Path(model).with_suffix(".resume.pt")


def load_checkpoint(path: pathlib.Path, settings: dict[str, Any]) -> dict[str, Any] | None:
    """The epoch checkpoint at ``path`` if there is one, checked to be of a run with these ``settings``; None if
    there is none. A checkpoint of other settings, or one that cannot be read, is a `ValueError` naming it."""
    if not path.exists():
        return None
    try:
        state = th.load(path, map_location="cpu", weights_only=False)
        stored = state["settings"]
    except Exception as err:  # a truncated or foreign file
        raise ValueError(f"{path} is not a readable distillation checkpoint ({err}); remove it to start over") from err
    if stored != settings:
        differ = sorted(k for k in settings.keys() | stored.keys() if settings.get(k) != stored.get(k))
        raise ValueError(f"{path} is the checkpoint of a run with other settings ({', '.join(differ)}); remove it "
                         "or give another --resume-file to start this one")
    return state


def loss_settings(loss: LossOptions) -> dict[str, Any]:
    """``loss`` as a checkpoint's settings record it: its fields, ``teacher_set`` only where it is on, so that a
    checkpoint written before that option existed still resumes under the same loss."""
    return {k: v for k, v in dataclasses.asdict(loss).items() if k != "teacher_set" or v}


def split_by_scene(shards: list[dataset.Shard], val_fraction: float) -> tuple[list[int], list[int]]:
    """State indices (over the shards in order) of the training and validation scenes: the last
    ``val_fraction`` of each shard series' scenes (``meta["series"]``) are validation. Series are
    collected apart (another driver, another machine), so each gives its share of held-out scenes, and a
    series added later does not become the validation set as a whole."""
    scenes: dict[int, list[list[int]]] = {}  # series -> its scenes in order -> their state indices
    first = 0
    for shard in shards:
        episodes = shard.arrays["state_episode"]
        own = scenes.setdefault(int(shard.meta["series"]), [])
        base = len(own)
        own.extend([] for _ in shard.meta["episodes"])
        for i, e in enumerate(episodes):
            own[base + int(e)].append(first + i)
        first += len(episodes)
    train: list[int] = []
    val: list[int] = []
    for own in scenes.values():
        n_val = int(round(len(own) * val_fraction))
        for k, states in enumerate(own):
            (val if k >= len(own) - n_val else train).extend(states)
    if not train:
        raise ValueError(f"{sum(len(o) for o in scenes.values())} scenes leave none for training at val_fraction "
                         f"{val_fraction}")
    return sorted(train), sorted(val)


def split_states(shards: list[dataset.Shard], val_fraction: float, masks: bool = True, progress: bool = True,
                 max_states: int | None = None) -> tuple[LabelledStates, LabelledStates | None]:
    """The training and validation states of ``shards`` (`split_by_scene`), labelled as `run` reads them
    (``masks``, ``progress``: its options); ``max_states``: the first that many training states only. None for
    the validation states where the split leaves none."""
    labelled = dataset.labelled_states(shards, masks=masks, progress=progress)
    train_idx, val_idx = split_by_scene(shards, val_fraction)
    if max_states is not None:
        train_idx = train_idx[:max_states]
    return labelled.subset(np.array(train_idx)), labelled.subset(np.array(val_idx)) if val_idx else None


def run(data: pathlib.Path, init: str, out: pathlib.Path, epochs: int, val_fraction: float = 0.2,
        max_states: int | None = None, batch_states: int = 16, loss: LossOptions = LossOptions(),
        learning_rate: float | None = None, seed: int = 0, max_shards: int | str | None = None,
        augment: bool = True, masks: bool = True, progress: bool = True, anchor: float = 0.0,
        average_last: int = 1, last_out: pathlib.Path | None = None,
        resume_file: pathlib.Path | None = None) -> dict[str, Any]:
    """Distil ``data`` into the model of ``init`` and save it as ``out``; returns the report. ``augment``:
    draw each batch's states through the model's own augmentation (its exact symmetries), as its training did.
    ``masks``: the teacher term ranges over every allowed action of a state (else its labelled actions).
    ``progress``: the progress term ranks a state's valid actions by the objects they sorted. ``anchor``:
    the weight that keeps unlabelled allowed actions at the starting model's values (0: none). ``loss``: the
    loss's margin, weights, radii, temperature and teacher set in training (`LossOptions`); the validation loss
    keeps the default weights and the teacher's action alone, so that recipes compare. ``average_last`` > 1: the
    saved model's weights are the mean of its weights at the end of each of the last that many epochs (one model
    from a stretch of training rather than the last step's draw; the report's ``averaged`` holds its validation);
    1: the last epoch's. ``last_out``: with
    ``average_last`` > 1, also save the last epoch's weights there (the model a run without averaging saves, since
    distillation is deterministic for a seed), its report beside it. ``resume_file``: the epoch checkpoint (default
    `resume_path` of ``out``; module docstring)."""
    from sb3_pixeldqn import PixelDoubleDQN

    if epochs < 1 or not 0 <= val_fraction < 1:
        raise ValueError(f"need epochs >= 1 and val_fraction in [0, 1), got {epochs} and {val_fraction}")
    if not 1 <= average_last <= epochs:
        raise ValueError(f"average_last must be between 1 and the epochs ({epochs}), got {average_last}")
    if last_out is not None and (average_last == 1 or pathlib.Path(last_out).resolve() == pathlib.Path(out).resolve()):
        raise ValueError("last_out needs average_last > 1 and a path other than out")
    val_loss = dataclasses.replace(loss, weights=DEFAULT_WEIGHTS, teacher_set=False)
    if not pathlib.Path(init).is_file():
        raise ValueError(f"--init {init!r} does not exist")
    model = PixelDoubleDQN.load(init, device="cpu")
    if learning_rate is not None:
        for group in model.policy.optimizer.param_groups:
            group["lr"] = learning_rate
    files = dataset.shard_files(data)
    stored = dataset.load_shard(files[0]).meta["layout"] if files else None
    if stored is not None and (list(stored["obs_shape"]) != list(model.observation_space.shape)
                               or len(stored["map_names"]) != model.policy.n_maps):
        raise ValueError(f"{init} takes observations {list(model.observation_space.shape)} and {model.policy.n_maps} "
                         f"maps; the dataset's are {stored['obs_shape']} and {stored['map_names']}")
    # every shard in the first one's layout (`load_shard`'s check, naming the shard), then a growing dataset's past
    shards = dataset.select_shards(dataset.load_dataset(data, expect_layout=stored), max_shards)
    train, val = split_states(shards, val_fraction, masks, progress, max_states)
    transforms = list(model.augment) if augment else []
    anchor_net = copy.deepcopy(model.q_net).requires_grad_(False) if anchor > 0 else None
    start = time.monotonic()
    history: list[dict[str, Any]] = []
    mean_net = AveragedModel(model.q_net) if average_last > 1 else None  # the equal-weight running mean
    checkpoint = resume_path(out) if resume_file is None else pathlib.Path(resume_file)
    settings = {"init_sha256": hashlib.sha256(pathlib.Path(init).read_bytes()).hexdigest(),
                "shards": [s.path.name for s in shards], "val_fraction": val_fraction, "max_states": max_states,
                "batch_states": batch_states, "loss": loss_settings(loss), "learning_rate": learning_rate,
                "seed": seed, "augment": augment, "masks": masks, "progress": progress, "anchor": anchor,
                "average_last": average_last, "epochs": epochs}
    resumed = load_checkpoint(checkpoint, settings)
    first_epoch, before = 0, 0.0
    if resumed is not None:  # go on after the last finished epoch
        model.q_net.load_state_dict(resumed["q_net"])
        model.q_net_target.load_state_dict(resumed["q_net_target"])
        model.policy.optimizer.load_state_dict(resumed["optimizer"])
        if mean_net is not None:
            mean_net.load_state_dict(resumed["mean_net"])
        history, first_epoch, before = resumed["history"], int(resumed["epoch"]), float(resumed["seconds"])
        print(json.dumps({"resumed": str(checkpoint), "after_epoch": first_epoch}), flush=True)
    elif val is not None:  # the starting model, for comparison
        history.append({"epoch": 0, "val": evaluate(model.policy, val, val_loss)})
        print(json.dumps(history[-1]), flush=True)
    for epoch in range(first_epoch, epochs):
        row: dict[str, Any] = {"epoch": epoch + 1, "train": distill(model, train, 1, batch_states, loss,
                                                                     seed=seed + epoch, augment=transforms,
                                                                     anchor=anchor, anchor_net=anchor_net)[0]}
        if val is not None:
            row["val"] = evaluate(model.policy, val, val_loss)
        history.append(row)
        print(json.dumps(row), flush=True)
        if mean_net is not None and epoch >= epochs - average_last:
            mean_net.update_parameters(model.q_net)
        state = {"settings": settings, "epoch": epoch + 1, "history": history,
                 "seconds": before + time.monotonic() - start, "q_net": model.q_net.state_dict(),
                 "q_net_target": model.q_net_target.state_dict(), "optimizer": model.policy.optimizer.state_dict(),
                 "mean_net": None if mean_net is None else mean_net.state_dict()}
        write_atomically(checkpoint, functools.partial(th.save, state))
    averaged: dict[str, Any] | None = None
    if last_out is not None:  # the last epoch's weights, before the mean replaces them
        model.save(last_out)
    if mean_net is not None:
        model.q_net.load_state_dict(mean_net.module.state_dict())
        model.q_net_target.load_state_dict(model.q_net.state_dict())
        averaged = {"epochs": average_last}
        if val is not None:
            averaged["val"] = evaluate(model.policy, val, val_loss)
        print(json.dumps({"averaged": averaged}), flush=True)
    model.save(out)
    report = {"data": str(data), "shards": [s.path.name for s in shards], "init": init, "out": str(out),
              "train_states": len(train.obs),
              "train_labels": len(train.label_action), "val_states": 0 if val is None else len(val.obs),
              "epochs": epochs, "augment": [repr(t) for t in transforms], "masks": masks, "progress": progress,
              "anchor": anchor, "margin": loss.margin, "teacher_radius": loss.teacher_radius,
              "teacher_weight": loss.weights[2], "progress_radius": loss.progress_radius,
              "progress_weight": loss.weights[3], "teacher_temperature": loss.teacher_temperature,
              "teacher_set": loss.teacher_set,
              "seed": seed, "batch_states": batch_states, "learning_rate": learning_rate,
              "average_last": average_last, **({"averaged": averaged} if averaged is not None else {}),
              "seconds": round(before + time.monotonic() - start, 1), "history": history}
    if last_out is not None:  # the plain model's report: this run's, without the mean
        plain = {k: v for k, v in report.items() if k != "averaged"} | {"out": str(last_out), "average_last": 1}
        write_json_atomically(report_path(last_out), plain)
    write_json_atomically(report_path(out), report)
    checkpoint.unlink(missing_ok=True)  # the run is done: nothing to go on from
    return report


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m shelf_env.training.distill", description=__doc__.split("\n")[0])
    p.add_argument("--data", type=pathlib.Path, default=pathlib.Path("data/teacher"), help="the dataset folder")
    p.add_argument("--init", default="examples/pretrained/v1/p_s.zip", help="the P+S zip whose Q-maps are trained")
    p.add_argument("--out", type=pathlib.Path, required=True, help="the distilled model (an SB3 zip)")
    p.add_argument("--epochs", type=int, default=10, help="passes over the training states")
    p.add_argument("--val-fraction", type=float, default=0.2, help="share of the scenes held out for validation")
    p.add_argument("--max-states", type=int, default=None, help="train on the first this many states only")
    p.add_argument("--batch-states", type=int, default=16, help="states per gradient step (all their labels)")
    p.add_argument("--margin", type=float, default=1.0, help="the ranking and teacher losses' margin")
    p.add_argument("--learning-rate", type=float, default=None, help="the optimiser's rate (default: the model's)")
    p.add_argument("--seed", type=int, default=0, help="seed of the batch order")
    p.add_argument("--max-shards", default=None, help="use the first this many shards (in name order), or of "
                   "each series named: 's00:55,s01:9'")
    p.add_argument("--no-augment", action="store_true", help="train on the states as stored (default: drawn "
                   "through the model's own augmentation)")
    p.add_argument("--teacher-over", choices=("masked", "labelled"), default="masked", help="the actions the "
                   "teacher's margin ranges over: every allowed action of the state, or its labelled actions only")
    p.add_argument("--no-progress", action="store_true", help="leave out the progress term (valid actions ranked "
                   "by the objects they sorted)")
    p.add_argument("--anchor", type=float, default=0.0, help="weight of the term that keeps unlabelled allowed "
                   "actions at the starting model's values (0: none)")
    p.add_argument("--teacher-radius", type=int, default=0, help="the teacher's action stands for the cells of "
                   "its map within this many cells (its object rather than one pixel; 0: the pixel)")
    p.add_argument("--teacher-weight", type=float, default=1.0, help="weight of the teacher term in training")
    p.add_argument("--teacher-temperature", type=float, default=0.0, help="> 0: the teacher term as a "
                   "cross-entropy of the allowed actions' softmax at this temperature (0: the margin)")
    p.add_argument("--teacher-set", action="store_true", help="the teacher's action stands for every labelled "
                   "action of its state as good by the labels (valid, sorting at least as many objects, where the "
                   "teacher's sorts one): ties the teacher broke by its own order are not pushed down")
    p.add_argument("--progress-weight", type=float, default=1.0, help="weight of the progress term in training")
    p.add_argument("--progress-radius", type=int, default=0, help="in the progress term the lower action stands "
                   "for the allowed cells of its map within this many cells (0: the pixel)")
    p.add_argument("--average-last", type=int, default=1, help="save the mean of the weights at the end of each of "
                   "the last this many epochs (1: the last epoch's weights)")
    p.add_argument("--last-out", type=pathlib.Path, default=None, help="with --average-last: also save the last "
                   "epoch's own weights (and their report) here")
    p.add_argument("--resume-file", type=pathlib.Path, default=None, help="the epoch checkpoint this run writes "
                   "and goes on from (default: NAME.resume.pt beside --out)")
    args = p.parse_args(argv)
    try:
        loss = LossOptions(args.margin, (1.0, 1.0, args.teacher_weight, args.progress_weight), args.teacher_radius,
                           args.progress_radius, args.teacher_temperature, args.teacher_set)
        run(args.data, args.init, args.out, args.epochs, args.val_fraction, args.max_states, args.batch_states,
            loss, args.learning_rate, args.seed, args.max_shards, augment=not args.no_augment,
            masks=args.teacher_over == "masked", progress=not args.no_progress, anchor=args.anchor,
            average_last=args.average_last, last_out=args.last_out, resume_file=args.resume_file)
    except ValueError as err:
        print(f"distill: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
