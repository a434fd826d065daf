"""A distilled model as a veto on the shipped P+S's choice (an experiment, camera-only at test time).

    python -m research.distilled_veto make --base examples/pretrained/v1/p_s.zip \\
        --veto runs/distill_scaling/p_s_d440_aug_mpa.zip --delta 1 --out results/distilled_veto/model/p_s_v440_d1.zip
    python -m research.distilled_veto falls results/distilled_veto/model/p_s_v440_d1.zip+veto --ns 8 --runs 10 \\
        --seed 2000 --out results/distilled_veto/falls.json      (shelf_env.evaluation.falls with +veto known)
    python -m research.evaluate --policies results/distilled_veto/model/p_s_v440_d1.zip+veto ...  (shelf-evaluate)

The distilled models (docs/experiments/distill-scaling.md) learned to rank the actions that drop an object
below safe ones (1–2.4 % invalid greedy actions per action on held-out scenes at N = 8 against the shipped
model's 16 %) but not to sort: their valid actions sort an object 13 % of the time, the shipped model's
39 %. This wrapper asks whether the two halves combine: the shipped model chooses, among the actions the
env allows, only from those the distilled model values within ``delta`` of its own best,

    keep = allowed & (Q_D(s, a) >= max_{allowed} Q_D(s, ·) − delta),   a = argmax_{keep} Q_P(s, ·),

so ``delta`` = 0 is the distilled model's greedy choice (up to ties) and a large ``delta`` the shipped
model's. The distillation's ranking term sets the scale: it puts a labelled fall at least a margin (1)
below a safe action of the same state.

``make`` writes a copy of the base checkpoint and, beside it, ``<stem>.veto.json`` (the distilled zip's
path and digest, ``delta``): the copy's file stem is the policy's label, so each (veto model, delta) has its
own cells. ``<zip>+veto`` plays the copy under `DistilledVeto`. ``margins`` says, on the labelled states
of the veto model's own validation scenes, what share of the labelled falls, valid actions and sorting
actions lie within each ``delta`` of its best allowed action (`veto_margins`): what a veto at that
``delta`` would let through.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import sys
from typing import Any

import gymnasium as gym
import numpy as np

from shelf_env import policies
from shelf_env.evaluation.protocol import policy_digest
from shelf_env.files import copy_atomically, write_json_atomically

#: Appended to a checkpoint's path: play it under `DistilledVeto` with the settings of `veto_path`.
VETO = "+veto"


class DistilledVeto:
    """Wrap ``policy`` (SB3's ``predict`` with ``action_masks``): before it chooses, the allowed actions are
    narrowed to those ``veto`` (a `PixelDoubleDQN` of the same layout) values within ``delta`` of its best
    allowed action (module docstring). ``stats``: ``decisions``, and ``vetoed``: the decisions where the
    policy's own choice was outside the kept set (so the veto changed the action)."""

    def __init__(self, policy: Any, veto: Any, delta: float) -> None:
        if not (math.isfinite(delta) and delta >= 0):
            raise ValueError(f"delta must be a finite number >= 0, got {delta}")
        self.policy, self.veto, self.delta = policy, veto, float(delta)
        self.observation_space, self.action_space = policy.observation_space, policy.action_space
        if tuple(veto.observation_space.shape) != tuple(self.observation_space.shape) or \
                int(veto.action_space.n) != int(self.action_space.n):
            raise ValueError(f"the veto model takes observations {tuple(veto.observation_space.shape)} and "
                             f"{int(veto.action_space.n)} actions; the policy {tuple(self.observation_space.shape)} "
                             f"and {int(self.action_space.n)}")
        self.stats = {"decisions": 0, "vetoed": 0}

    def kept(self, observation: np.ndarray, allowed: np.ndarray) -> np.ndarray:
        """The allowed actions (flat bool) the veto model values within ``delta`` of its best allowed one."""
        q = self.veto.policy.q_map_values(np.asarray(observation)).reshape(-1)
        if not allowed.any():
            return allowed
        return allowed & (q >= q[allowed].max() - self.delta)

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        obs = np.asarray(observation)
        if obs.shape != self.observation_space.shape:
            raise ValueError(f"DistilledVeto acts on one observation of shape {self.observation_space.shape}, "
                             f"got {obs.shape}")
        allowed = (np.ones(int(self.action_space.n), bool) if action_masks is None
                   else np.asarray(action_masks, bool).reshape(-1))
        keep = self.kept(obs, allowed)
        own, _ = self.policy.predict(obs, state=state, deterministic=deterministic, action_masks=allowed)
        self.stats["decisions"] += 1
        if keep[int(own)]:
            return own, state
        self.stats["vetoed"] += 1
        return self.policy.predict(obs, state=state, deterministic=deterministic, action_masks=keep)


def veto_path(checkpoint: str | os.PathLike) -> pathlib.Path:
    """The settings a ``<checkpoint>+veto`` policy reads: ``<stem>.veto.json`` beside the checkpoint."""
    path = pathlib.Path(checkpoint)
    return path.with_name(path.stem + ".veto.json")


REMAKE = "python -m research.distilled_veto make rewrites it"


def read_settings(base: str) -> tuple[pathlib.Path, float]:
    """(the veto model's path, delta) of ``base``'s settings; `ValueError` naming what is wrong."""
    path = veto_path(base)
    if not path.is_file():
        raise ValueError(f"policy {base}{VETO}: no settings at {path} (python -m research.distilled_veto "
                         f"make writes them)")
    try:
        settings = json.loads(path.read_text())
        model = pathlib.Path(settings["veto"])
        digest, delta = str(settings["veto_sha256"]), float(settings["delta"])
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not JSON ({err}); {REMAKE}") from err
    except KeyError as err:
        raise ValueError(f"{path}: no {err.args[0]!r} setting; {REMAKE}") from err
    except (TypeError, ValueError) as err:
        raise ValueError(f"{path}: a setting of the wrong type ({err})") from err
    if not math.isfinite(delta) or delta < 0:
        raise ValueError(f"{path}: delta must be a finite number >= 0, got {delta}")
    if not model.is_file():
        raise ValueError(f"{path}: the veto model {model} does not exist")
    if policy_digest(str(model)) != digest:
        raise ValueError(f"{path}: the veto model {model} is not the one the settings were made with (sha256)")
    return model, delta


def _check(base: str) -> None:
    if base in policies.POLICIES:
        raise ValueError(f"{VETO} narrows a checkpoint's choice with a distilled model; {base!r} is not a checkpoint")
    read_settings(base)


def _wrap(agent: Any, env: gym.Env, base: str) -> DistilledVeto:
    from sb3_pixeldqn import PixelDoubleDQN

    model, delta = read_settings(base)
    return DistilledVeto(agent, PixelDoubleDQN.load(model, device="cpu"), delta)


policies.register_wrapper(VETO, _wrap, check=_check, files=lambda base: [veto_path(base)])


def make(base: pathlib.Path, veto: pathlib.Path, delta: float, out: pathlib.Path) -> pathlib.Path:
    """Copy ``base`` to ``out`` and write ``out``'s settings (``veto``, its digest, ``delta``) beside it."""
    for name, path in (("--base", base), ("--veto", veto)):
        if not path.is_file():
            raise ValueError(f"{name} {path} does not exist")
    if not (math.isfinite(delta) and delta >= 0):
        raise ValueError(f"--delta must be a finite number >= 0, got {delta}")
    if out.suffix != ".zip":
        raise ValueError(f"--out must be a .zip (the policy's label is its stem), got {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    copy_atomically(base, out)
    write_json_atomically(veto_path(out), {"base": str(base), "veto": str(veto),
                                           "veto_sha256": policy_digest(str(veto)), "delta": delta})
    return out


def gaps(q: np.ndarray, masks: np.ndarray, label_state: np.ndarray, label_action: np.ndarray) -> np.ndarray:
    """How far each labelled action's value lies below its state's best allowed action: ``q`` (S, n_actions),
    ``masks`` (S, n_actions) bool, labels (K,) -> (K,), 0 for the best one; a veto at ``delta`` keeps the
    labels with a gap <= delta."""
    best = np.where(masks, q, -np.inf).max(axis=1)
    return best[label_state] - q[label_state, label_action]


def veto_margins(model_path: pathlib.Path, data: pathlib.Path, deltas: list[float],
                 val_fraction: float = 0.2) -> dict[str, Any]:
    """What a veto at each ``delta`` keeps on the validation scenes of the veto model's own distillation
    (its ``.distill.json``'s shards, split as `shelf_env.training.distill` split them): the share of the
    labelled actions that dropped an object, of the valid ones and of those that sorted an object whose
    value lies within ``delta`` of the model's best allowed action of their state."""
    from sb3_pixeldqn import PixelDoubleDQN
    from shelf_env.privileged import dataset
    from shelf_env.training.distill import split_by_scene

    report_path = model_path.with_suffix(".distill.json")
    if not report_path.is_file():
        raise ValueError(f"{report_path} does not exist: the veto model's distillation report names its shards")
    report = json.loads(report_path.read_text())
    shards = [dataset.load_shard(data / name) for name in report["shards"]]
    _, val = split_by_scene(shards, val_fraction)
    if len(val) != report["val_states"]:
        raise ValueError(f"the split at val_fraction {val_fraction} gives {len(val)} validation states; "
                         f"{report_path} had {report['val_states']}")
    states = dataset.labelled_states(shards).subset(np.array(val))
    model = PixelDoubleDQN.load(model_path, device="cpu")
    n = int(model.action_space.n)
    q = np.concatenate([model.policy.q_map_values(states.obs[i:i + 32]).reshape(-1, n)
                        for i in range(0, len(states.obs), 32)])
    masks = states.unpacked_masks(n)
    assert masks is not None and states.label_progress is not None
    gap = gaps(q, masks, states.label_state, states.label_action)
    groups = {"fell": states.label_invalid, "valid": ~states.label_invalid,
              "sorted": ~states.label_invalid & (states.label_progress > 0)}
    return {"model": str(model_path), "val_states": len(val),
            "labels": {k: int(v.sum()) for k, v in groups.items()},
            "kept": {f"{d:g}": {k: float(np.mean(gap[v] <= d)) if v.any() else None for k, v in groups.items()}
                     for d in deltas}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m research.distilled_veto", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    m = sub.add_parser("make", help="a copy of the base checkpoint with its veto settings beside it")
    m.add_argument("--base", type=pathlib.Path, default=pathlib.Path("examples/pretrained/v1/p_s.zip"))
    m.add_argument("--veto", type=pathlib.Path, required=True, help="the distilled model (an SB3 zip)")
    m.add_argument("--delta", type=float, required=True, help="kept: within this of the veto model's best")
    m.add_argument("--out", type=pathlib.Path, required=True, help="the copy (.zip); its stem is the label")
    g = sub.add_parser("margins", help="what a veto at each delta keeps of the veto model's validation labels")
    g.add_argument("models", type=pathlib.Path, nargs="+", help="distilled zips (their .distill.json beside them)")
    g.add_argument("--data", type=pathlib.Path, default=pathlib.Path("data/teacher"))
    g.add_argument("--deltas", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0, 2.0])
    g.add_argument("--out", type=pathlib.Path, default=None, help="also write the results here (JSON)")
    sub.add_parser("falls", help="python -m shelf_env.evaluation.falls with +veto registered (its arguments follow)",
                   add_help=False)
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["falls"]:
        from shelf_env.evaluation import falls

        return falls.main(argv[1:])
    args = p.parse_args(argv)
    try:
        if args.command == "margins":
            results = [veto_margins(m, args.data, args.deltas) for m in args.models]
            print(json.dumps(results, indent=1))
            if args.out is not None:
                write_json_atomically(args.out, results)
            return 0
        print(make(args.base, args.veto, args.delta, args.out))
    except ValueError as err:
        print(f"distilled_veto: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
