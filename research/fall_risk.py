"""A learned fall-risk map: which picks drop an object, predicted from the camera alone.

Issue 10's learned policies lose most of their open-loop episodes to falls: objects dragged out of
the cabinet by the carry of a pick (`results/models/falls.md`). The privileged lookahead
(`shelf_env.privileged.lookahead`) avoids them by trying each pick in a forked copy of the simulator, which a
robot cannot do. Reinforcement learning from the episodes' terminal rewards did not teach the
Q-maps to avoid them either (docs/experiments/): a fall is one terminal transition per
episode, and the Q-value of a 10 % risky pick is close to that of a safe one under the paper's
reward. This module learns the risk directly, as a supervised problem with dense labels:

- `collect_episode` plays a training scene (training objects, seeds of their own) and, at every
  step, tries several picks in forked copies of the env (`shelf_env.privileged.lookahead.probe_outcome`): the
  H-d candidate of every visible object, one random graspable cell of every visible object, and
  the greedy pick of a driving model. Each probe is a label: did the pick end the episode invalid
  (an object fell, the scene did not come to rest)? The step it then executes is a safe one when
  there is one (the driving model's when safe, else the first safe H-d candidate, and a random
  safe probe with probability ``explore``), so episodes reach the cluttered states of late steps.
- `train_fall_risk` fits a `FallRiskModel` (the residual FCN of Fig. 4, one logit per cell, started
  from a P+S model's pick FCN) with a binary cross-entropy at the probed cells only, mirrored
  images and renamed classes (`shelf_env.symmetry`) as augmentation; it keeps the epoch and picks
  the decision threshold that do best on held-out training episodes.
- `FallFilter` (the product's, `shelf_env.fall_filter`) wraps a policy at test time: it masks out
  the pick cells whose predicted risk is over the threshold, and the policy chooses among the rest
  (a Q-map policy: its best remaining action, a push where every pick is masked). It reads only
  the observation, so a robot can run it; the labels it learned from came from the simulator, in
  training only.

Commands (``python -m research.fall_risk -h``): ``collect`` (resumable, one file per episode,
shardable over processes), ``train`` (on those episodes, or on the pick labels of the teacher dataset,
`shelf_env.privileged.dataset`), ``threshold`` (`rethreshold`), ``check`` (`greedy_check`), ``penalty``
(`penalty_check`: the risk pooled over objects, as a mask or a soft penalty). Evaluations name a filtered
checkpoint ``<checkpoint>+fall-filter``: importing this module registers that wrapper
(`shelf_env.policies`), which loads the model ``<stem>.fall_risk.pt`` beside the checkpoint
(`fall_filter_path`); ``python -m research.evaluate`` is shelf-evaluate with it registered.

Measured (docs/experiments/fall-filter.md; ``bash results/fall_filter/run.sh``): 33 minutes of collection on
two cores (1,551 states) give a held-out AUC of 0.77; the filter halves the invalid share of the
shipped P+S's choice among the probed picks of held-out training episodes, but on issue 10's YCB
scenes it cut the share of actions that drop an object only from 4.7 to 3.4 % and sorted no more.
Trained on the teacher dataset's 157,095 pick labels (docs/experiments/teacher-fall-filter.md;
``bash results/teacher_fall_filter/run.sh``) the AUC is 0.845, about +0.011 per doubling of the states;
the shipped P+S under it had fewer falls and sorted no more on validation scenes, while a perfect
filter (the labels themselves) would have made its choices both safe and better. From scratch (``--init none``)
the AUC is 0.866 and levels off; pooling over objects and a soft penalty do no better than the mask
(docs/experiments/object-fall-penalty.md), and an unoccluded top-down view ranks the falls no better than the
camera (docs/experiments/fall-visibility.md).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import pathlib
import sys
import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
import torch.nn.functional as F

from sb3_pixeldqn.networks import DEFAULT_WIDTHS, ResidualFCN
from shelf_env import params, policies
from shelf_env.baselines.heuristics import ObservationView, object_blobs
from shelf_env.fall_filter import FallFilter
from shelf_env.files import write_atomically, write_json_atomically
from shelf_env.privileged.lookahead import LookaheadDistance, probe_outcome
from shelf_env.symmetry import PermuteClasses

#: Seed of the collection's scenes (`collect_seed`): no evaluation or training run draws from it.
COLLECT_SEED = 7001
#: Most picks probed per state (each costs one env action).
MAX_PROBES = 12


def collect_seed(shard: int, episode: int) -> int:
    """Reset seed of collection episode ``episode`` of shard ``shard``."""
    return int(np.random.SeedSequence([COLLECT_SEED, shard, episode]).generate_state(1)[0])


def probe_cells(hd: LookaheadDistance, view: ObservationView, greedy: tuple[int, int] | None,
                rng: np.random.Generator, max_probes: int = MAX_PROBES) -> list[tuple[int, int]]:
    """The pick cells to label in one state: H-d's candidates (one per visible unsorted object, or
    the uncovering picks when all look sorted), the driving model's greedy pick, then one random
    graspable cell per visible object; without repeats, at most ``max_probes``. ``hd``: the episode's
    H-d lookahead (only its candidate lists are used here, no probe)."""
    cells = hd.candidates(view) or hd.uncover_candidates(view)
    if greedy is not None:
        cells.append(greedy)
    for b in rng.permutation(np.unique(view.blob[view.graspable])):
        rows, cols = np.nonzero(view.graspable & (view.blob == b))
        i = int(rng.integers(len(rows)))
        cells.append((int(rows[i]), int(cols[i])))
    return list(dict.fromkeys((int(r), int(c)) for r, c in cells))[:max_probes]


def collect_episode(env: gym.Env, model: Any, reset_seed: int, rng: np.random.Generator,
                    explore: float = 0.2, max_probes: int = MAX_PROBES) -> dict[str, np.ndarray]:
    """Play one scene from ``reset_seed`` and label picks at every step (see the module docstring).

    Returns ``obs`` (T, C, H, W) uint8, the observations labelled, and ``probes`` (K, 4) int64 rows
    ``(t, row, col, invalid)``: pick cell (row, col) of observation t ended the episode invalid (1)
    or not (0). ``model``: a `PixelDoubleDQN` (or anything with its ``predict``) whose greedy pick is
    probed and preferred when safe; None to drive with H-d's safe candidates only.
    """
    base: Any = env.unwrapped
    codec = base.codec
    hd = LookaheadDistance(env)
    obs, _ = env.reset(seed=reset_seed)
    observations: list[np.ndarray] = []
    probes: list[tuple[int, int, int, int]] = []
    for _ in range(base.max_actions):
        view = ObservationView.from_observation(obs, hd.margin_cells)
        if not view.graspable.any():
            break
        greedy_action = None if model is None else policies.masked_greedy(model, env, obs)
        greedy = None
        if greedy_action is not None:
            name, row, col = codec.decode(greedy_action)
            greedy = (row, col) if name == "pick" else None
        cells = probe_cells(hd, view, greedy, rng, max_probes)
        safe = []
        for row, col in cells:
            invalid = not probe_outcome(env, codec.encode("pick", row, col)).valid
            probes.append((len(observations), row, col, int(invalid)))
            if not invalid:
                safe.append((row, col))
        observations.append(np.asarray(obs, dtype=np.uint8))
        if safe and rng.random() < explore:
            row, col = safe[int(rng.integers(len(safe)))]
            choice = codec.encode("pick", row, col)
        elif greedy_action is not None and (greedy is None or greedy in safe):
            choice = greedy_action  # the model's own action when it is a push or a safe pick
        elif safe:
            choice = codec.encode("pick", *safe[0])
        else:
            break  # every probed pick drops something: nothing safe to show from here
        obs, _, terminated, truncated, _ = env.step(choice)
        if terminated or truncated:
            break
    if not observations:
        shape = base.observation_space.shape
        return {"obs": np.zeros((0, *shape), np.uint8), "probes": np.zeros((0, 4), np.int64)}
    return {"obs": np.stack(observations), "probes": np.asarray(probes, dtype=np.int64).reshape(-1, 4)}


def save_episode(path: pathlib.Path, data: dict[str, np.ndarray], meta: np.ndarray) -> None:
    """One episode's ``obs``, ``probes`` and ``meta`` (JSON) as a compressed ``.npz`` at exactly ``path``."""
    with open(path, "wb") as f:
        np.savez_compressed(f, meta=meta, obs=data["obs"], probes=data["probes"])


def episode_path(out: pathlib.Path, shard: int, episode: int) -> pathlib.Path:
    return out / f"shard{shard:02d}_ep{episode:05d}.npz"


def collect(out: pathlib.Path, episodes: int, shard: int = 0, ns: tuple[int, ...] = tuple(range(3, 15)),
            model_path: str | None = None, object_set: str = "train", explore: float = 0.2,
            hours: float | None = None) -> int:
    """Collect ``episodes`` episodes of shard ``shard`` into ``out`` (one ``.npz`` per episode, written
    atomically; episodes already on disk are skipped, so a stopped collection resumes). N of each
    episode is drawn from ``ns`` with the episode's own seed. Stops early after ``hours``. Returns
    the number of episodes written now."""
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    if not ns or min(ns) < 1:
        raise ValueError(f"ns must be numbers of objects >= 1, got {ns}")
    if not 0.0 <= explore <= 1.0:
        raise ValueError(f"explore must be a probability in [0, 1], got {explore}")
    model = None
    primitives: tuple[str, ...] = ("pick", "push")
    pixel_size = params.PIXEL_SIZE
    if model_path is not None:
        from sb3_pixeldqn import PixelDoubleDQN
        from shelf_env.evaluation.protocol import checkpoint_pixel_size, checkpoint_primitives

        primitives, pixel_size = checkpoint_primitives(model_path), checkpoint_pixel_size(model_path)
        model = PixelDoubleDQN.load(model_path, device="cpu")
    start, written = time.monotonic(), 0
    envs: dict[int, gym.Env] = {}
    try:
        for episode in range(episodes):
            path = episode_path(out, shard, episode)
            if path.exists():
                continue
            if hours is not None and time.monotonic() - start > hours * 3600:
                break
            seed = collect_seed(shard, episode)
            rng = np.random.default_rng(seed)
            n = int(ns[int(rng.integers(len(ns)))])
            if n not in envs:
                envs[n] = gym.make("ShelfSort-v0", num_objects=n, object_set=object_set, primitives=primitives,
                                   pixel_size=pixel_size)
            data = collect_episode(envs[n], model, seed, rng, explore)
            meta = np.array(json.dumps({"num_objects": n, "reset_seed": seed, "object_set": object_set,
                                        "model": model_path, "explore": explore, "pixel_size": pixel_size}))
            write_atomically(path, functools.partial(save_episode, data=data, meta=meta))
            written += 1
            labels = data["probes"][:, 3]
            print(f"shard {shard} episode {episode}: N={n}, {len(data['obs'])} states, {len(labels)} probes, "
                  f"{int(labels.sum())} invalid", flush=True)
    finally:
        for env in envs.values():
            env.close()
    return written


def load_dataset(folder: pathlib.Path) -> list[dict[str, np.ndarray]]:
    """Every collected episode of ``folder`` (sorted by name), as dicts of ``obs`` and ``probes``."""
    files = sorted(folder.glob("shard*_ep*.npz"))
    if not files:
        raise ValueError(f"no collected episodes (shard*_ep*.npz) and no teacher dataset shards (sNN_NNNNN.npz) "
                         f"in {folder}")
    episodes = []
    for f in files:
        with np.load(f) as data:
            if len(data["obs"]):
                episodes.append({"obs": data["obs"], "probes": data["probes"]})
    return episodes


def coordinate_grid(rows: int, cols: int) -> th.Tensor:
    """``(2, rows, cols)``: each cell's depth (row / (rows - 1), 0 at row 0) and its distance from the centre
    line (|column - (cols - 1) / 2| / (cols / 2)), the same for a cell and its mirror image."""
    depth = th.linspace(0.0, 1.0, rows).view(rows, 1).expand(rows, cols)
    centre = (th.arange(cols, dtype=th.float32) - (cols - 1) / 2).abs() / (cols / 2)
    return th.stack([depth, centre.view(1, cols).expand(rows, cols)])


class FallRiskModel(th.nn.Module):
    """Observation ``(B, C, H, W)`` uint8 -> logit of "a pick here ends the episode invalid", ``(B, H, W)``.

    ``coords``: two more input channels, each cell's depth (its row over the rows) and its distance from
    the cabinet's centre line (|column - centre| over half the columns). A fully convolutional net sees
    a scene's layout only through its receptive field; whether a carry drags an object out depends on
    where in the cabinet the pick is. The distance is symmetric, so the mirror stays an exact symmetry."""

    def __init__(self, in_channels: int, widths: tuple[int, int, int] = DEFAULT_WIDTHS,
                 threshold: float = 0.5, coords: bool = False) -> None:
        super().__init__()
        self.coords = bool(coords)
        self.fcn = ResidualFCN(in_channels + 2 * self.coords, widths)
        self.in_channels, self.widths = in_channels, tuple(int(w) for w in widths)
        self.threshold = float(threshold)
        self.info: dict[str, Any] = {}  # what training reported (`train_fall_risk`), set by `load`

    def forward(self, obs: th.Tensor) -> th.Tensor:
        x = obs.float() / 255.0
        if self.coords:
            rows, cols = x.shape[-2:]
            x = th.cat([x, coordinate_grid(rows, cols).expand(len(x), 2, rows, cols)], dim=1)
        return self.fcn(x)

    def start_from(self, fcn: th.nn.Module) -> None:
        """Copy a pick FCN's weights (a P+S / S model's, same widths); with ``coords`` the coordinate channels'
        input weights start at zero, so the copy computes the same map until training moves them."""
        state = fcn.state_dict()
        if self.coords:
            stem = state["stem.weight"]
            state["stem.weight"] = th.cat([stem, th.zeros(stem.shape[0], 2, *stem.shape[2:])], dim=1)
        self.fcn.load_state_dict(state)

    def risk(self, obs: np.ndarray) -> np.ndarray:
        """Predicted probability per cell, ``(H, W)`` for one observation or ``(B, H, W)`` for a batch."""
        x = th.as_tensor(np.asarray(obs))
        single = x.dim() == 3
        with th.no_grad():
            p = th.sigmoid(self(x[None] if single else x)).numpy()
        return p[0] if single else p

    def save(self, path: str | pathlib.Path, info: dict[str, Any] | None = None) -> None:
        """Weights and settings in one torch file, written atomically."""
        payload = {"state_dict": self.state_dict(), "in_channels": self.in_channels, "widths": self.widths,
                   "threshold": self.threshold, "coords": self.coords, "info": info or {}}
        write_atomically(path, lambda tmp: th.save(payload, tmp))

    @classmethod
    def load(cls, path: str | pathlib.Path) -> FallRiskModel:
        path = pathlib.Path(path)
        if not path.is_file():
            raise ValueError(f"fall-risk model {str(path)!r} does not exist "
                             "(python -m research.fall_risk train makes one)")
        try:
            payload = th.load(path, map_location="cpu", weights_only=True)
            model = cls(int(payload["in_channels"]), tuple(payload["widths"]), float(payload["threshold"]),
                        bool(payload.get("coords", False)))
            model.load_state_dict(payload["state_dict"])
        except Exception as err:  # noqa: BLE001  (any failure to read is a bad file)
            raise ValueError(f"{path} is not a readable fall-risk model: {err}") from err
        model.info = payload.get("info", {})
        model.eval()
        return model


@dataclass
class Split:
    obs: th.Tensor  # (S, C, H, W) uint8
    state: th.Tensor  # (K,) index into obs
    cell: th.Tensor  # (K,) flat cell index
    label: th.Tensor  # (K,) float 0/1
    objects: np.ndarray | None = None  # (S,) objects in each state's scene, where the data says (a teacher dataset)
    sorted_change: np.ndarray | None = None  # (K,) change in sorted objects the labelled pick made (a teacher dataset)


def make_split(episodes: list[dict[str, np.ndarray]]) -> Split:
    obs, state, cell, label, offset = [], [], [], [], 0
    for ep in episodes:
        cols = ep["obs"].shape[-1]
        obs.append(th.as_tensor(ep["obs"]))
        p = th.as_tensor(ep["probes"])
        state.append(p[:, 0] + offset)
        cell.append(p[:, 1] * cols + p[:, 2])
        label.append(p[:, 3].float())
        offset += len(ep["obs"])
    return Split(th.cat(obs), th.cat(state), th.cat(cell), th.cat(label))


def teacher_split(shards: list[Any], states: np.ndarray, source: str | None = None) -> Split:
    """The pick labels of the teacher dataset's states ``states`` (indices over ``shards`` in order,
    `shelf_env.training.distill.split_by_scene`'s): label 1 where the pick ended the episode invalid
    (``label_valid`` false: an object fell or the scene did not come to rest). Pushes are left out:
    the filter masks picks. ``source``: only the labels of that origin (`shelf_env.privileged.dataset.SOURCES`,
    e.g. ``"greedy"``: the driving model's own choice)."""
    from shelf_env.privileged.dataset import SOURCES

    if source is not None and source not in SOURCES:
        raise ValueError(f"source must be one of {SOURCES}, got {source!r}")
    obs, state, cell, label, objects, dsorted, first = [], [], [], [], [], [], 0
    local = np.full(sum(s.num_states for s in shards), -1, np.int64)
    local[states] = np.arange(len(states))
    for shard in shards:
        a = shard.arrays
        cells = int(np.prod(a["obs"].shape[-2:]))
        pick = list(shard.meta["layout"]["map_names"]).index("pick")
        mine = local[first:first + shard.num_states]
        keep = (mine[a["label_state"]] >= 0) & (a["label_action"] // cells == pick)
        if source is not None:
            keep &= a["label_source"] == SOURCES.index(source)
        obs.append(a["obs"][mine >= 0])
        scene_objects = np.array([int(e["num_objects"]) for e in shard.meta["episodes"]])
        objects.append(scene_objects[a["state_episode"][mine >= 0]])
        state.append(mine[a["label_state"][keep]])
        cell.append(a["label_action"][keep] % cells)
        label.append(~a["label_valid"][keep].astype(bool))
        dsorted.append(a["label_dsorted"][keep].astype(np.int64))
        first += shard.num_states
    return Split(th.as_tensor(np.concatenate(obs)), th.as_tensor(np.concatenate(state)),
                 th.as_tensor(np.concatenate(cell)), th.as_tensor(np.concatenate(label), dtype=th.float32),
                 np.concatenate(objects), np.concatenate(dsorted))


def state_groups(states: np.ndarray) -> list[np.ndarray]:
    """Per state index present in ``states`` (in increasing order), the positions of its entries (ascending)."""
    order = np.argsort(states, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(states[order])) + 1) if len(order) else []


def spread_labels(split: Split) -> Split:
    """``split`` with each state's pick labels spread over their objects: every cell of an object (a blob of one
    class colour, `object_blobs`) that holds a labelled pick takes the outcome of the nearest labelled pick on
    it (Chebyshev distance in cells; the mean where several are equally near, a soft target). A labelled cell on
    no object keeps its own label. Why: a pick's outcome is nearly the same anywhere on its object
    (docs/experiments/fall-visibility.md), so the labels of a few cells stand for the whole object."""
    labels, cells, states = split.label.numpy(), split.cell.numpy(), split.state.numpy()
    cols = split.obs.shape[-1]
    out_state, out_cell, out_label = [], [], []
    for index in state_groups(states):
        t = int(states[index[0]])
        blob = object_blobs(split.obs[t].numpy()).reshape(-1)
        mine = blob[cells[index]]
        off = index[mine < 0]  # labelled cells on no object
        out_state.append(np.full(len(off), t))
        out_cell.append(cells[off])
        out_label.append(labels[off])
        for b in np.unique(mine[mine >= 0]):
            own = index[mine == b]
            target = np.flatnonzero(blob == b)
            dist = np.maximum(np.abs(target[:, None] // cols - cells[own][None] // cols),
                              np.abs(target[:, None] % cols - cells[own][None] % cols))
            nearest = dist == dist.min(axis=1, keepdims=True)
            out_state.append(np.full(len(target), t))
            out_cell.append(target)
            out_label.append((nearest * labels[own][None]).sum(axis=1) / nearest.sum(axis=1))
    return Split(split.obs, th.as_tensor(np.concatenate(out_state) if out_state else np.zeros(0, np.int64)),
                 th.as_tensor(np.concatenate(out_cell) if out_cell else np.zeros(0, np.int64)),
                 th.as_tensor(np.concatenate(out_label) if out_label else np.zeros(0), dtype=th.float32),
                 split.objects, None)


def split_teacher_shards(shards: list[Any], val_fraction: float, max_states: int | None = None,
                         name: str = "the dataset") -> tuple[Split, Split, np.ndarray]:
    """`load_splits` on loaded teacher-dataset shards: the training and held-out splits (split by scene,
    `shelf_env.training.distill.split_by_scene`; with ``max_states`` the first that many training states only),
    and the held-out states' indices over ``shards`` in order."""
    from shelf_env.training.distill import split_by_scene

    train, val = split_by_scene(shards, val_fraction)
    if max_states is not None:
        if max_states < 1:
            raise ValueError(f"max_states must be >= 1, got {max_states}")
        train = train[:max_states]
    if not val:
        raise ValueError(f"{name}: {len(shards)} shards leave no held-out scene at val_fraction {val_fraction}")
    return teacher_split(shards, np.array(train)), teacher_split(shards, np.array(val)), np.array(val)


def load_splits(data: pathlib.Path, val_fraction: float, max_shards: str | None = None,
                max_states: int | None = None) -> tuple[Split, Split]:
    """The training and held-out splits of ``data``: a teacher dataset (``sNN_NNNNN.npz`` shards,
    `shelf_env.privileged.dataset`; split by scene as the distillation splits it, ``max_shards`` and
    ``max_states`` as its ``--max-shards`` and ``--max-states``: the first that many training states only,
    the held-out scenes unchanged) or a folder of collected episodes (`collect`; the last ``val_fraction``
    of the episodes by file name held out)."""
    from shelf_env.privileged import dataset

    if not 0 < val_fraction < 1:
        raise ValueError(f"need 0 < val_fraction < 1, got {val_fraction}")
    if dataset.shard_files(data):
        train, val, _ = split_teacher_shards(dataset.select_shards(dataset.load_dataset(data), max_shards),
                                             val_fraction, max_states, str(data))
        return train, val
    if max_shards is not None or max_states is not None:
        raise ValueError(f"max_shards and max_states select a teacher dataset's shards and states; {data} holds "
                         "none (sNN_NNNNN.npz)")
    episodes = load_dataset(data)
    n_val = max(1, int(round(len(episodes) * val_fraction)))
    if len(episodes) - n_val < 1:
        raise ValueError(f"{data} has {len(episodes)} episodes with states; need at least 2 for a held-out split")
    return make_split(episodes[:-n_val]), make_split(episodes[-n_val:])


def logits_at(model: FallRiskModel, obs: th.Tensor, index: th.Tensor, cells: th.Tensor,
              mirror: bool = False) -> th.Tensor:
    """The model's logit at each (observation ``obs[index[k]]``, flat cell ``cells[k]``), one FCN pass
    per observation; with ``mirror`` on the left-right mirrored images (and cells)."""
    width = obs.shape[-1]
    if mirror:
        obs = th.flip(obs, dims=(-1,))
        cells = (cells // width) * width + (width - 1 - cells % width)
    return model(obs).flatten(1)[index, cells]


def scores(model: FallRiskModel, split: Split, chunk: int = 64) -> np.ndarray:
    """Predicted probabilities at every labelled probe of ``split``."""
    out = np.zeros(len(split.label), np.float32)
    with th.no_grad():
        for s0 in range(0, len(split.obs), chunk):
            sel = (split.state >= s0) & (split.state < s0 + chunk)
            if sel.any():
                logits = model(split.obs[s0:s0 + chunk]).flatten(1)
                out[sel.numpy()] = th.sigmoid(logits[split.state[sel] - s0, split.cell[sel]]).numpy()
    return out


def auc(labels: np.ndarray, p: np.ndarray) -> float:
    """Area under the ROC curve (the probability that a random positive scores above a random negative)."""
    pos, neg = p[labels == 1], p[labels == 0]
    if not len(pos) or not len(neg):
        return float("nan")
    both = np.concatenate([pos, neg])
    values, inverse = np.unique(both, return_inverse=True)
    order = np.argsort(both, kind="stable")
    ranks = np.empty(len(both))
    ranks[order] = np.arange(1, len(both) + 1)
    ranks = (np.bincount(inverse, ranks) / np.bincount(inverse))[inverse]  # ties share their mean rank
    return float((ranks[:len(pos)].sum() - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def pick_threshold(labels: np.ndarray, p: np.ndarray) -> float:
    """The threshold that maximises balanced accuracy (mean of the recall of falls and of safe picks)."""
    best, best_t = -1.0, 0.5
    for t in np.linspace(0.05, 0.95, 19):
        flagged = p >= t
        recall = flagged[labels == 1].mean() if (labels == 1).any() else 0.0
        specificity = (~flagged[labels == 0]).mean() if (labels == 0).any() else 0.0
        if (recall + specificity) / 2 > best:
            best, best_t = (recall + specificity) / 2, float(t)
    return best_t


def recall_threshold(labels: np.ndarray, p: np.ndarray, recall: float) -> float:
    """The highest threshold (on a grid of 0.01) that still flags at least ``recall`` of the falls:
    the filter that keeps the most safe picks among those that catch that share of the falls."""
    if not 0 < recall <= 1:
        raise ValueError(f"recall must be in (0, 1], got {recall}")
    pos = p[labels == 1]
    if not len(pos):
        raise ValueError("no fall among the held-out labels: no threshold reaches a recall")
    grid = np.round(np.arange(0.01, 1.0, 0.01), 2)
    ok = [t for t in grid if (pos >= t).mean() >= recall]
    return float(max(ok)) if ok else float(grid[0])


def threshold_report(labels: np.ndarray, p: np.ndarray, threshold: float) -> dict[str, float]:
    """The recall of falls and of safe picks at ``threshold`` (NaN where the labels hold none)."""
    flagged = p >= threshold
    return {"threshold": threshold,
            "val_recall_invalid": float(flagged[labels == 1].mean()) if (labels == 1).any() else float("nan"),
            "val_recall_valid": float((~flagged[labels == 0]).mean()) if (labels == 0).any() else float("nan")}


def train_fall_risk(data: pathlib.Path, out: pathlib.Path, init: str | None = None, epochs: int = 8,
                    batch: int = 32, lr: float = 3e-4, val_fraction: float = 0.15, seed: int = 0,
                    max_shards: str | None = None, recall: float | None = None,
                    max_states: int | None = None, coords: bool = False, spread: bool = False) -> dict[str, Any]:
    """Fit a `FallRiskModel` on ``data`` (see the module docstring; `load_splits`: collected episodes,
    or a teacher dataset's pick labels) and save it to ``out``. The held-out split (the last
    ``val_fraction`` of the episodes, or of each series' scenes) chooses the epoch whose weights rank
    its labels best (AUC) and the threshold: the best balanced accuracy, or with ``recall`` the highest
    that flags that share of the held-out falls (`recall_threshold`). The returned report (also the
    file's ``info``) gives their AUC and the recall of falls and of safe picks at the threshold.
    ``init``: a P+S / S zip whose pick FCN starts the model. ``coords``: `FallRiskModel`'s coordinate channels.
    ``spread``: train on the labels spread over their objects (`spread_labels`; the held-out labels unchanged)."""
    if epochs < 1 or batch < 1 or not 0 < val_fraction < 1:
        raise ValueError(f"need epochs >= 1, batch >= 1 and 0 < val_fraction < 1; got {epochs}, {batch}, "
                         f"{val_fraction}")
    if recall is not None and not 0 < recall <= 1:
        raise ValueError(f"recall must be in (0, 1], got {recall}")
    train, val = load_splits(data, val_fraction, max_shards, max_states)
    labelled = len(train.label)
    if spread:
        train = spread_labels(train)
    model, history, best_epoch = fit_fall_risk(train, val, init, epochs, batch, lr, seed, coords)
    p, labels = scores(model, val), val.label.numpy()
    model.threshold = pick_threshold(labels, p) if recall is None else recall_threshold(labels, p, recall)
    report = {"obs_shape": list(train.obs.shape[1:]), "data": str(data), "max_shards": max_shards,
              "max_states": max_states,
              "val_fraction": val_fraction, "recall_target": recall,
              "train_states": len(train.obs), "train_probes": labelled, "train_targets": len(train.label),
              "train_invalid": float(train.label.sum()) if spread else int(train.label.sum()), "spread": spread,
              "val_states": len(val.obs), "val_probes": len(labels), "val_invalid": int(labels.sum()),
              "val_auc": auc(labels, p), **threshold_report(labels, p, model.threshold),
              "epochs": epochs, "best_epoch": best_epoch,
              "init": init, "coords": coords, "history": history}
    model.save(out, report)
    return report


def fit_fall_risk(train: Split, val: Split, init: str | None = None, epochs: int = 8, batch: int = 32,
                  lr: float = 3e-4, seed: int = 0, coords: bool = False
                  ) -> tuple[FallRiskModel, list[dict[str, float]], int]:
    """`train_fall_risk`'s fit on given splits: a `FallRiskModel` (started from ``init``'s pick FCN) trained
    ``epochs`` epochs on ``train``'s labels, with the weights of the epoch whose AUC on ``val`` is best.
    Returns the model (its threshold unset: 0.5), the per-epoch history and that epoch."""
    th.manual_seed(seed)
    model = FallRiskModel(int(train.obs.shape[1]), coords=coords)
    if init is not None:
        from sb3_pixeldqn import PixelDoubleDQN

        model.start_from(PixelDoubleDQN.load(init, device="cpu").policy.q_net.fcns["pick"])
    positives = float(train.label.mean())
    pos_weight = th.tensor((1 - positives) / max(positives, 1e-6))
    optimizer = th.optim.Adam(model.parameters(), lr=lr, weight_decay=2e-5)
    rng = np.random.default_rng(seed)
    states = np.arange(len(train.obs))
    label_state = train.state.numpy()
    of_state = [np.zeros(0, np.int64)] * len(states)  # each state's label positions, found once, not per batch
    for index in state_groups(label_state):
        of_state[int(label_state[index[0]])] = index
    in_chunk = np.full(len(states), -1, np.int64)
    permute = PermuteClasses()
    history: list[dict[str, float]] = []
    best: tuple[float, int, dict[str, th.Tensor]] = (-1.0, epochs, {})
    for epoch in range(epochs):
        model.train()
        losses = []
        for chunk in np.array_split(rng.permutation(states), max(1, len(states) // batch)):
            sel = th.as_tensor(np.sort(np.concatenate([of_state[s] for s in chunk])))  # the chunk's labels, in order
            if not len(sel):
                continue
            in_chunk[chunk] = np.arange(len(chunk))
            idx = th.as_tensor(in_chunk[label_state[sel.numpy()]])
            images = train.obs[th.as_tensor(chunk)]
            perm = rng.permutation(3)
            if (perm != np.arange(3)).any():  # falls do not depend on a class: rename the classes
                images = th.as_tensor(np.stack([permute.observation(o, perm) for o in images.numpy()]))
            mirror = bool(rng.random() < 0.5)
            logits = logits_at(model, images, idx, train.cell[sel], mirror)
            loss = F.binary_cross_entropy_with_logits(logits, train.label[sel], pos_weight=pos_weight)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            losses.append(float(loss.detach()))
        model.eval()
        p = scores(model, val)
        history.append({"epoch": epoch + 1, "train_loss": float(np.mean(losses)), "val_auc": auc(val.label.numpy(), p)})
        print(json.dumps(history[-1]), flush=True)
        if history[-1]["val_auc"] > best[0]:  # keep the epoch that ranks held-out picks best
            best = (history[-1]["val_auc"], epoch + 1, {k: v.clone() for k, v in model.state_dict().items()})
    if best[2]:  # (with no held-out fall to rank, the AUC is undefined and the last epoch stays)
        model.load_state_dict(best[2])
    return model, history, best[1]


#: Thresholds `greedy_check` sweeps, beside the model's own.
SWEEP = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
#: How `object_pooled` spreads a per-cell risk over the object under the cell.
POOLINGS = ("cell", "mean", "max")
#: The soft penalties `penalty_check` tries, in units of the spread of the checkpoint's pick Q-values.
PENALTIES = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)


def object_pooled(risk: np.ndarray, obs: np.ndarray, pooling: str) -> np.ndarray:
    """``risk`` (H, W) with every object cell set to the mean (``"mean"``) or maximum (``"max"``) risk of
    its object: the blob of one class colour it belongs to in ``obs`` (`object_blobs`; touching objects of
    one class are one blob). Cells on no object keep their own risk; ``"cell"`` returns ``risk`` unchanged.
    Why: most falls belong to the object a pick lifts, not to the cell it lifts it by."""
    if pooling not in POOLINGS:
        raise ValueError(f"pooling must be one of {POOLINGS}, got {pooling!r}")
    if pooling == "cell":
        return risk
    blob = object_blobs(obs)
    on = blob >= 0
    if not on.any():
        return risk
    n = int(blob.max()) + 1
    if pooling == "mean":
        per = np.bincount(blob[on], risk[on], n) / np.bincount(blob[on], minlength=n)
    else:
        per = np.full(n, -np.inf)
        np.maximum.at(per, blob[on], risk[on])
    out = np.array(risk, dtype=np.float64, copy=True)
    out[on] = per[blob[on]]
    return out


def choose(groups: list[np.ndarray], values: np.ndarray, risk: np.ndarray | None = None,
           threshold: float | None = None, penalty: float | None = None) -> np.ndarray:
    """Per state (``groups``: the indices of its labels), the label a choice lands on: the highest value
    among the labels at risk below ``threshold`` (all of them where none is), or the highest
    ``values - penalty * risk``. No risk, or neither: the highest value."""
    out = np.empty(len(groups), np.int64)
    for k, index in enumerate(groups):
        q = values[index]
        if risk is None:
            pass
        elif penalty is not None:
            q = q - penalty * risk[index]
        elif threshold is not None:
            kept = risk[index] < threshold
            if kept.any():
                q = np.where(kept, q, -np.inf)
        out[k] = index[int(np.argmax(q))]
    return out


def held_out_scores(data: pathlib.Path, risk: FallRiskModel, checkpoint: str, val_fraction: float | None = None,
                    poolings: tuple[str, ...] = ("cell",)) -> tuple[Split, np.ndarray, dict[str, np.ndarray],
                                                                  list[np.ndarray]]:
    """The held-out split of ``data`` the fall-risk model was trained with (`load_splits` with its
    ``val_fraction`` and ``max_shards``), the checkpoint's pick Q-value at each of its labels, the risk
    at each label under each of ``poolings`` (`object_pooled`), and per state the indices of its labels."""
    info = getattr(risk, "info", {})
    fraction = val_fraction if val_fraction is not None else float(info.get("val_fraction", 0.15))
    _, val = load_splits(data, fraction, info.get("max_shards"))
    values, groups = pick_values(checkpoint, val)
    cells, states = val.cell.numpy(), val.state.numpy()
    scored = {how: np.zeros(len(cells)) for how in poolings}
    for index in groups:
        obs = val.obs[int(states[index[0]])].numpy()
        p = risk.risk(obs)
        for how in poolings:
            scored[how][index] = object_pooled(p, obs, how).reshape(-1)[cells[index]]
    return val, values, scored, groups


def pick_values(checkpoint: str, split: Split) -> tuple[np.ndarray, list[np.ndarray]]:
    """The checkpoint's pick Q-value at each label of ``split`` (read from its observations), and per state
    (in order) the indices of its labels."""
    from sb3_pixeldqn import PixelDoubleDQN

    model = PixelDoubleDQN.load(checkpoint, device="cpu")
    pick = [name for name, _ in model.policy.maps].index("pick")
    cells, states = split.cell.numpy(), split.state.numpy()
    values = np.zeros(len(cells))
    groups = state_groups(states)
    for index in groups:
        values[index] = model.policy.q_map_values(split.obs[int(states[index[0]])].numpy())[pick].reshape(-1)[
            cells[index]]
    return values, groups


def greedy_check(data: pathlib.Path, risk: FallRiskModel, checkpoint: str,
                 val_fraction: float | None = None) -> dict[str, Any]:
    """What the filter does to a model's choice on the held-out split of ``data`` (`load_splits`, with the
    ``val_fraction`` and ``max_shards`` the fall-risk model was trained with, so the same split): at
    each state, the pick the model values most among the labelled cells, and the one it values most
    among those the filter keeps (itself where none is kept), with the share of each that ended the
    episode invalid in the forked copy, beside the share of all labelled picks; and how well the
    fall-risk model ranks those labels (AUC), overall and, on a teacher dataset, per number of objects. On a
    teacher dataset also the mean change in sorted objects of each choice (``greedy_sorted``,
    ``filtered_sorted``: a fall counts as its label says), what the filter costs in progress. ``sweep``:
    the filtered choice's invalid share (and change in sorted objects) at each threshold of `SWEEP`;
    ``oracle_*``: the same under a perfect filter (the labels themselves), what the checkpoint's ranking of
    the safe picks gives when no fall gets through; ``q_auc``: how well the checkpoint's own Q-values rank the
    same labels (low value as risk)."""
    val, values, pooled, groups = held_out_scores(data, risk, checkpoint, val_fraction)
    scored = pooled["cell"]
    labels, states = val.label.numpy(), val.state.numpy()

    def choices(threshold: float, risky: np.ndarray = scored) -> np.ndarray:
        return choose(groups, values, risky, threshold)

    def outcome(chosen: np.ndarray, name: str) -> dict[str, float]:
        result = {f"{name}_invalid": float(labels[chosen].mean()) if len(chosen) else float("nan")}
        if val.sorted_change is not None and len(chosen):
            result[f"{name}_sorted"] = float(val.sorted_change[chosen].mean())
        return result

    out: dict[str, Any] = {"checkpoint": checkpoint, "threshold": risk.threshold, "val_states": len(groups),
                           "probes_invalid": float(labels.mean()), **outcome(choices(np.inf), "greedy"),
                           **outcome(choices(risk.threshold), "filtered"), "auc": auc(labels, scored),
                           "q_auc": auc(labels, -values)}
    out["sweep"] = [{"threshold": t, **outcome(choices(t), "filtered")} for t in SWEEP]
    out.update(outcome(choices(0.5, labels), "oracle"))  # a perfect filter: the labels themselves
    if val.objects is not None:
        n_of_label = val.objects[states]
        out["by_objects"] = {int(n): {"labels": int((n_of_label == n).sum()),
                                      "invalid": float(labels[n_of_label == n].mean()),
                                      "auc": auc(labels[n_of_label == n], scored[n_of_label == n])}
                             for n in np.unique(n_of_label)}
    return out


def penalty_check(data: pathlib.Path, risk: FallRiskModel, checkpoint: str, poolings: tuple[str, ...] = POOLINGS,
                  thresholds: tuple[float, ...] = SWEEP, penalties: tuple[float, ...] = PENALTIES,
                  max_invalid: float = 0.06, val_fraction: float | None = None) -> dict[str, Any]:
    """The fall risk pooled over objects and used as a mask or as a soft penalty, offline
    (docs/experiments/object-fall-penalty.md): on the held-out split of ``data`` (`held_out_scores`), for
    each of ``poolings`` the AUC of the pooled risk on the pick labels, and the invalid share and mean
    change in sorted objects of the checkpoint's choice among the labelled picks under each rule: ``hard``
    (mask risk >= t, t in ``thresholds``) and ``soft`` (highest Q - lambda * sigma * risk, lambda in
    ``penalties``, sigma the standard deviation of the Q-values at all the labels). ``unfiltered`` and
    ``oracle`` (a perfect filter) for reference. ``candidate``: `penalty_candidate` with ``max_invalid``."""
    val, values, scored, groups = held_out_scores(data, risk, checkpoint, val_fraction, poolings)
    if val.sorted_change is None:
        raise ValueError(f"{data} is not a teacher dataset (sNN_NNNNN.npz): its labels carry no change in sorted "
                         "objects to weigh a penalty against")
    return {"checkpoint": checkpoint, **penalty_report(val.label.numpy(), val.sorted_change, values, scored, groups,
                                                       thresholds, penalties, max_invalid)}


def penalty_report(labels: np.ndarray, dsorted: np.ndarray, values: np.ndarray, scored: dict[str, np.ndarray],
                   groups: list[np.ndarray], thresholds: tuple[float, ...] = SWEEP,
                   penalties: tuple[float, ...] = PENALTIES, max_invalid: float = 0.06) -> dict[str, Any]:
    """`penalty_check`'s report on given arrays: per label its fall (``labels``), change in sorted objects
    and checkpoint Q-value, and under each name of ``scored`` (a pooling, a view) the risk at each label;
    ``groups``: per state the indices of its labels."""

    def outcome(chosen: np.ndarray) -> dict[str, float]:
        return {"invalid": float(labels[chosen].mean()), "sorted": float(dsorted[chosen].mean())}

    sigma = float(values.std())
    out: dict[str, Any] = {"val_states": len(groups), "labels": len(labels), "q_sigma": sigma,
                           "max_invalid": max_invalid, "unfiltered": outcome(choose(groups, values)),
                           "oracle": outcome(choose(groups, values, labels, threshold=0.5)), "poolings": {}}
    for how, r in scored.items():
        out["poolings"][how] = {
            "auc": auc(labels, r),
            "hard": [{"threshold": t, **outcome(choose(groups, values, r, threshold=t))} for t in thresholds],
            "soft": [{"penalty": lam, **outcome(choose(groups, values, r, penalty=lam * sigma))}
                     for lam in penalties]}
    out["candidate"] = penalty_candidate(out, max_invalid)
    return out


def penalty_candidate(result: dict[str, Any], max_invalid: float) -> dict[str, Any] | None:
    """The plan's offline rule on a `penalty_check` result: among the settings (pooling, hard threshold or
    soft penalty) whose choices sort at least as much per choice as the unfiltered choice and are invalid
    at most ``max_invalid`` of the time, the one with the lowest invalid share (ties: the more sorted);
    None if none qualifies."""
    floor = result["unfiltered"]["sorted"]
    ok = [{"pooling": how, "rule": rule, **entry}
          for how, block in result["poolings"].items() for rule in ("hard", "soft") for entry in block[rule]
          if entry["sorted"] >= floor and entry["invalid"] <= max_invalid]
    return min(ok, key=lambda e: (e["invalid"], -e["sorted"])) if ok else None


def rethreshold(model_path: pathlib.Path, data: pathlib.Path, recall: float, out: pathlib.Path) -> dict[str, Any]:
    """Save a copy of the fall-risk model at ``model_path`` to ``out`` whose threshold flags ``recall`` of
    the held-out falls of ``data`` (the split it was trained with; `recall_threshold`), so that two
    filters of one training can be played side by side (each ``<stem>.fall_risk.pt`` beside its own
    checkpoint copy). Returns the copy's ``info``."""
    risk = FallRiskModel.load(model_path)
    _, val = load_splits(data, float(risk.info.get("val_fraction", 0.15)), risk.info.get("max_shards"))
    p, labels = scores(risk, val), val.label.numpy()
    risk.threshold = recall_threshold(labels, p, recall)
    info = {**risk.info, "recall_target": recall, **threshold_report(labels, p, risk.threshold),
            "rethresholded_from": str(model_path)}
    risk.save(out, info)
    return info


#: Appended to a checkpoint's path: play it under `FallFilter` with the fall-risk model of `fall_filter_path`.
FALL_FILTER = "+fall-filter"


def fall_filter_path(checkpoint: str | os.PathLike) -> pathlib.Path:
    """The learned fall-risk model a ``<checkpoint>+fall-filter`` policy uses: ``<stem>.fall_risk.pt``
    beside the checkpoint (``python -m research.fall_risk train --init <checkpoint>`` makes one)."""
    path = pathlib.Path(checkpoint)
    return path.with_name(path.stem + ".fall_risk.pt")


def _check_filtered(base: str) -> None:
    if base in policies.POLICIES:
        raise ValueError(f"{FALL_FILTER} filters a checkpoint's picks with the fall-risk model saved beside it; "
                         f"{base!r} is not a checkpoint")
    model = fall_filter_path(base)
    if not model.is_file():
        raise ValueError(f"policy {base}{FALL_FILTER}: no fall-risk model at {model} (python -m "
                         f"research.fall_risk train --init {base} --out {model} makes one)")


def _filtered(agent: Any, env: gym.Env, base: str) -> FallFilter:
    unwrapped: Any = env.unwrapped
    return FallFilter(agent, FallRiskModel.load(fall_filter_path(base)), unwrapped.map_names, unwrapped.rows,
                      unwrapped.cols)


policies.register_wrapper(FALL_FILTER, _filtered, check=_check_filtered, files=lambda base: [fall_filter_path(base)])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.fall_risk", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("collect", help="label picks in forked copies of training scenes (resumable)")
    c.add_argument("--out", type=pathlib.Path, required=True)
    c.add_argument("--episodes", type=int, required=True, help="episodes of this shard (those on disk are skipped)")
    c.add_argument("--shard", type=int, default=0)
    c.add_argument("--ns", type=int, nargs="+", default=list(range(3, 15)))
    c.add_argument("--model", default="examples/pretrained/v1/p_s.zip", help="driving model ('none': H-d only)")
    c.add_argument("--object-set", default="train")
    c.add_argument("--explore", type=float, default=0.2)
    c.add_argument("--hours", type=float, default=None)
    t = sub.add_parser("train", help="fit the fall-risk model on collected episodes")
    t.add_argument("--data", type=pathlib.Path, required=True)
    t.add_argument("--out", type=pathlib.Path, required=True,
                   help="the model file; <stem>.fall_risk.pt beside a checkpoint for <checkpoint>+fall-filter")
    t.add_argument("--init", default="examples/pretrained/v1/p_s.zip", help="zip whose pick FCN starts it ('none')")
    t.add_argument("--epochs", type=int, default=8)
    t.add_argument("--batch", type=int, default=32)
    t.add_argument("--val-fraction", type=float, default=0.15,
                   help="held-out share: of the episodes, or of each series' scenes of a teacher dataset")
    t.add_argument("--max-shards", default=None, help="a teacher dataset's shards to use (the distillation's option)")
    t.add_argument("--max-states", type=int, default=None,
                   help="a teacher dataset's first that many training states only (its held-out scenes unchanged)")
    t.add_argument("--coords", action="store_true", help="add the depth and centre-distance channels")
    t.add_argument("--spread", action="store_true", help="spread the training labels over their objects")
    t.add_argument("--recall", type=float, default=None,
                   help="threshold: the highest that flags this share of the held-out falls (default: the best "
                        "balanced accuracy)")
    r = sub.add_parser("threshold", help="a copy of a fall-risk model with the threshold of another recall")
    r.add_argument("--data", type=pathlib.Path, required=True)
    r.add_argument("--model", type=pathlib.Path, required=True)
    r.add_argument("--recall", type=float, required=True)
    r.add_argument("--out", type=pathlib.Path, required=True)
    k = sub.add_parser("check", help="the filter's effect on a model's choice among the probed picks, held out")
    k.add_argument("--data", type=pathlib.Path, required=True)
    k.add_argument("--model", type=pathlib.Path, required=True, help="the fall-risk model (.pt)")
    k.add_argument("--checkpoint", required=True, help="the P+S / S zip whose choice is filtered")
    k.add_argument("--out", type=pathlib.Path, default=None, help="also write the result here (JSON)")
    e = sub.add_parser("penalty", help="the risk pooled over objects, as a mask or a soft penalty, held out")
    e.add_argument("--data", type=pathlib.Path, required=True)
    e.add_argument("--model", type=pathlib.Path, required=True, help="the fall-risk model (.pt)")
    e.add_argument("--checkpoint", required=True, help="the P+S / S zip whose choice is penalised")
    e.add_argument("--max-invalid", type=float, default=0.06, help="the candidate's largest invalid share")
    e.add_argument("--out", type=pathlib.Path, default=None, help="also write the result here (JSON)")
    args = parser.parse_args(argv)
    try:  # a bad input is one line on stderr and exit status 2, before anything is written
        if args.command == "penalty":
            result = penalty_check(args.data, FallRiskModel.load(args.model), args.checkpoint,
                                   max_invalid=args.max_invalid)
            print(json.dumps(result, indent=1))
            if args.out is not None:
                write_json_atomically(args.out, result)
        elif args.command == "check":
            result = greedy_check(args.data, FallRiskModel.load(args.model), args.checkpoint)
            print(json.dumps(result, indent=1))
            if args.out is not None:
                write_json_atomically(args.out, result)
        elif args.command == "collect":
            model = None if args.model == "none" else args.model
            collect(args.out, args.episodes, args.shard, tuple(args.ns), model, args.object_set, args.explore,
                    args.hours)
        elif args.command == "threshold":
            info = rethreshold(args.model, args.data, args.recall, args.out)
            print(json.dumps({k: v for k, v in info.items() if k != "history"}, indent=1))
        else:
            init = None if args.init == "none" else args.init
            report = train_fall_risk(args.data, args.out, init, args.epochs, args.batch, val_fraction=args.val_fraction,
                                     max_shards=args.max_shards, recall=args.recall, max_states=args.max_states,
                                     coords=args.coords, spread=args.spread)
            print(json.dumps({k: v for k, v in report.items() if k != "history"}, indent=1))
    except ValueError as err:
        print(f"python -m research.fall_risk {args.command}: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
