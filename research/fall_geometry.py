"""Named fall geometry against the learned fall model (docs/experiments/fall-geometry.md).

Per labelled pick of the teacher dataset, the quantities of `shelf_env.fall_filter.geometry_features`, read
from the stored camera observation only: the pick cell on its object, the object's size and height, the
carry corridor to the opening (`shelf_env.conditions.safe_picks`'s geometry), its neighbours, the occluded
cells around it, its class's region and the scene (`FEATURES`); with ``blockers`` also the objects the carry
would hit (`BLOCKER_FEATURES`). The features, the model and the filter are the product's
(`shelf_env.fall_filter`); this module fits and measures them. Commands:

- `features`: the features of the fall model's split (`research.fall_risk.load_splits`) and, with
  ``--fresh``, of a test set of shards no fall model read -> one ``.npz``;
- `fit`: a logistic regression and an MLP (`FeatureModel`) on the training features, each feature's own AUC,
  the from-scratch fall model's risk joined to the features (two-fold by scene, `twofold`) and averaged with
  the MLP (`ensemble`), on validation and test -> a JSON report (``--checkpoint``: the offline check of
  `research.fall_risk.penalty_report` with each risk);
- `channels`: the fall model's recipe with the features as more input channels (`feature_channels`);
- `export`: a fitted model as a per-cell risk (`GeometryRisk`) beside a checkpoint, which
  ``<zip>+geometry-filter`` plays under `shelf_env.fall_filter.FallFilter` (registered by `shelf_env.policies`);
- `greedy`: exported risks on the picks a driving policy made, by N and by the picked object's height
  (`greedy_report`; docs/experiments/fall-model-refit.md, docs/experiments/wide-objects.md);
- `kinds`: the kinds of object a driving policy's picks took and the kinds that fell, by replaying the shards' scenes
  (`kinds_report`; docs/experiments/ycb-kinds.md);
- `carry`: whether the camera saw each greedy pick's carry as clear, by what the pick did in a `kinds` report
  (`carry_view`);
- `probe`: a set of another object set's scenes (unseen YCB objects, or the `train-wide` objects) in a folder of its
  own, never the teacher dataset (`probe`).

``features``, ``fit``, ``channels`` and ``greedy`` take ``--fresh-after``, so that a refit on a grown dataset keeps an
older test set that sits inside ``--max-shards``, and ``--extra-data``, a folder (such as a probe's) whose shards join
the pool as series of their own.

Measured: round two's MLP ranks the falls at AUC 0.902 on validation and 0.926 on the test set (the fall
model 0.866 / 0.897); as a mask at 0.1 on the shipped P+S it sorted 113 of the 270 validation scenes against
99 (docs/experiments/fall-geometry.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th

from research import fall_risk
from shelf_env.fall_filter import (
    FEATURES,
    FeatureModel,
    GeometryRisk,
    feature_names,
    geometry_features,
)
from shelf_env.files import write_atomically, write_json_atomically


def split_features(split: fall_risk.Split, blockers: bool = False) -> np.ndarray:
    """`geometry_features` of every label of ``split``, in the split's label order."""
    out = np.zeros((len(split.label), len(feature_names(blockers))), np.float32)
    cells, states = split.cell.numpy(), split.state.numpy()
    for index in fall_risk.state_groups(states):
        out[index] = geometry_features(split.obs[int(states[index[0]])].numpy(), cells[index], blockers)
    return out


@dataclasses.dataclass
class Sets:
    """The labelled picks a run reads, from one load of the dataset: the fall model's training and validation
    splits, each validation state's scene, and the test set (`fresh_split`; None without ``fresh``)."""

    train: fall_risk.Split
    val: fall_risk.Split
    val_scene: np.ndarray
    test: fall_risk.Split | None


def load_sets(data: pathlib.Path, val_fraction: float, max_shards: str | None, fresh: str | None = None,
              fresh_after: str | None = None, extra: Sequence[pathlib.Path] = ()) -> Sets:
    """`Sets` of the teacher dataset ``data``: the split of `research.fall_risk.load_splits` (``max_shards``,
    ``val_fraction``), the scene of each validation state (the two-fold split of `twofold` keeps a scene's
    states together) and, with ``fresh``, the test set (`fresh_split`: ``fresh``'s shards that ``fresh_after``,
    by default ``max_shards``, leaves out). The test set's shards are left out of the training and validation
    splits, so that a refit on a grown dataset can keep an older test set that sits inside ``max_shards``. Every
    shard of each ``extra`` folder (another object set's series, kept out of ``data``) joins the pool and is split by
    scene as its own series."""
    if not 0 < val_fraction < 1:
        raise ValueError(f"need 0 < val_fraction < 1, got {val_fraction}")
    shards, test = _pool(data, max_shards, fresh, fresh_after, extra)
    train, val, val_index = fall_risk.split_teacher_shards(shards, val_fraction, name=str(data))
    scene = np.concatenate([shard.arrays["state_episode"].astype(np.int64) + 1000 * k
                            for k, shard in enumerate(shards)])
    return Sets(train, val, scene[val_index], None if test is None else _whole(test))


def _pool(data: pathlib.Path, max_shards: str | None, fresh: str | None, fresh_after: str | None,
          extra: Sequence[pathlib.Path] = ()) -> tuple[list[Any], list[Any] | None]:
    """The shards a split is drawn from (``max_shards`` without the test set's, then every shard of each ``extra``
    folder) and the test set's shards. A shard name that two folders share is refused: each folder's series must be
    its own, or the split by scene would mix them."""
    from shelf_env.privileged import dataset

    if fresh_after is not None and fresh is None:
        raise ValueError("--fresh-after names what a test set comes after; give the test set with --fresh")
    every = dataset.load_dataset(data)
    test = None if fresh is None else _fresh_shards(every, max_shards if fresh_after is None else fresh_after,
                                                    fresh)
    left_out = {s.path.name for s in test or []}
    shards = [s for s in dataset.select_shards(every, max_shards) if s.path.name not in left_out]
    if not shards:
        raise ValueError(f"--max-shards {max_shards} selects no shard outside the test set --fresh {fresh}")
    seen = {s.path.name: data for s in every}
    for folder in extra:
        more = dataset.load_dataset(folder)  # refuses a folder without shards
        for shard in more:
            if shard.path.name in seen:
                raise ValueError(f"--extra-data {folder}: shard {shard.path.name} is also in {seen[shard.path.name]}; "
                                 "an extra folder's series must be its own")
            seen[shard.path.name] = folder
        shards += more
    return shards, test


#: The groups of N that `greedy_report` breaks its invalid picks down by.
N_GROUPS = ((3, 6), (7, 10), (11, 14))
#: The edges (metres) of the picked object's observed height (``object_max_height``) that `greedy_report` breaks its
#: invalid picks down by: under 6 cm, 6-9, 9-12, 12 cm and over (the training objects stop at 12 cm).
HEIGHT_EDGES = (0.06, 0.09, 0.12)


def greedy_report(data: pathlib.Path, val_fraction: float, max_shards: str | None, fresh: str | None,
                  fresh_after: str | None, series: str, risks: dict[str, pathlib.Path],
                  bands: tuple[float, ...] = (0.02, 0.05, 0.1), all_states: bool = False,
                  extra: Sequence[pathlib.Path] = ()) -> dict[str, Any]:
    """How exported `GeometryRisk` models (``risks``: name -> file) rank the picks a driving policy made: the
    greedy picks (label source ``greedy``) of ``series``' states (one series or several, ``"s90,s91"``) in the
    validation split of `load_sets` (every state with ``all_states``: a probe set no model read), and, for contrast,
    every other labelled pick of the same states; ``extra`` folders join the pool as in `load_sets`. Per set: the
    picks and the invalid ones per group of N (`N_GROUPS`); per risk and set: the AUC, the invalid share and count
    per band of the risk (edges ``bands``), and the share of the invalid picks at or over each risk's threshold.
    Per set also the picks and invalid ones per band of the picked object's observed height (`HEIGHT_EDGES`)."""
    models = {name: GeometryRisk.load(path) for name, path in risks.items()}
    chosen, states = series_states(data, val_fraction, max_shards, fresh, fresh_after, series, all_states, extra)
    picks = {"greedy": fall_risk.teacher_split(chosen, states, source="greedy")}
    every = fall_risk.teacher_split(chosen, states)
    picks["others"] = _without(every, picks["greedy"])
    out: dict[str, Any] = {"series": series, "states": int(len(states)), "bands": list(bands),
                           "all_states": all_states, "object_sets": sorted({str(s.meta.get("object_set"))
                                                                             for s in chosen})}
    edges = np.array((0.0, *bands, np.inf))
    for set_name, split in picks.items():
        y = split.label.numpy().astype(bool)
        entry: dict[str, Any] = {"picks": int(len(y)), "invalid": float(y.mean()) if len(y) else float("nan")}
        if split.objects is not None:  # by the scene's number of objects: sets of other N mixes compare
            n = split.objects[split.state.numpy()]
            entry["by_n"] = {f"{lo}-{hi}": {"picks": int(((n >= lo) & (n <= hi)).sum()),
                                            "invalid": int(y[(n >= lo) & (n <= hi)].sum())}
                             for lo, hi in N_GROUPS}
        x = split_features(split, True)  # a risk without the blocker features reads the first columns
        height = np.digitize(x[:, FEATURES.index("object_max_height")], HEIGHT_EDGES)
        entry["by_height"] = {label: {"picks": int((height == b).sum()), "invalid": int(y[height == b].sum())}
                              for b, label in enumerate(height_labels())}
        for name, risk in models.items():
            r = risk.model.risk(x if risk.blockers else x[:, :len(FEATURES)])
            band = np.digitize(r, edges[1:-1])
            entry[name] = {"auc": fall_risk.auc(y.astype(np.float64), r) if 0 < y.sum() < len(y) else float("nan"),
                           "bands": [{"picks": int((band == b).sum()), "invalid": int(y[band == b].sum())}
                                     for b in range(len(edges) - 1)],
                           "invalid_over_threshold": float((r[y] >= risk.threshold).mean()) if y.any() else 0.0,
                           "masked_at_threshold": float((r >= risk.threshold).mean()) if len(r) else 0.0}
        out[set_name] = entry
    return out


def series_states(data: pathlib.Path, val_fraction: float, max_shards: str | None, fresh: str | None,
                  fresh_after: str | None, series: str, all_states: bool = False,
                  extra: Sequence[pathlib.Path] = ()) -> tuple[list[Any], np.ndarray]:
    """The shards of ``series`` (one or several, ``"s90,s91"``) in the pool of `load_sets` and the indices (over
    those shards in order) of their states in its validation split, or of every state with ``all_states``."""
    from shelf_env.training.distill import split_by_scene

    if not 0 < val_fraction < 1:
        raise ValueError(f"need 0 < val_fraction < 1, got {val_fraction}")
    shards, _ = _pool(data, max_shards, fresh, fresh_after, extra)
    prefixes = tuple(f"{name.strip()}_" for name in series.split(","))
    chosen = [s for s in shards if s.path.name.startswith(prefixes)]
    if not chosen:
        raise ValueError(f"no shard of series {series!r} among --max-shards {max_shards}")
    # split_by_scene holds out the last scenes of each series apart, so the chosen series' split is the pool's
    states = (np.arange(sum(s.num_states for s in chosen)) if all_states
              else np.array(split_by_scene(chosen, val_fraction)[1], np.int64))
    if len(states) == 0:
        raise ValueError(f"series {series} has no state in the validation split")
    return chosen, states


def kinds_report(data: pathlib.Path, val_fraction: float, max_shards: str | None, fresh: str | None,
                 fresh_after: str | None, series: str, all_states: bool = False, extra: Sequence[pathlib.Path] = (),
                 rate: float = 0.053) -> dict[str, Any]:
    """Which kinds of object the picks of ``series``' states (chosen as `greedy_report` does) took, and which
    kinds fell: each episode is replayed from its reset seed through its executed actions, and at each chosen
    state whose replayed observation equals the stored one bit for bit (the others are counted and left out)
    each labelled pick's kind is the kind of the object under its cell in the env's observed semantic map.
    Every invalid greedy pick is stepped again in a forked copy (`_step_in_copy`) for the kinds that left the
    cabinet and those left not at rest. Per kind: the states it is in, its greedy picks and other picks and how
    many ended invalid, and its excess over ``rate`` (the training objects' greedy invalid share), ``invalid -
    rate * picks``, with the one-sided binomial p of that many or more (docs/experiments/ycb-kinds.md)."""
    if not 0 < rate < 1:
        raise ValueError(f"need 0 < rate < 1, got {rate}")
    chosen, states = series_states(data, val_fraction, max_shards, fresh, fresh_after, series, all_states, extra)
    kinds: dict[str, dict[str, Any]] = {}
    invalid_greedy: list[dict[str, Any]] = []
    replayed = mismatched = first = 0
    for shard in chosen:
        mine = states[(states >= first) & (states < first + shard.num_states)] - first
        first += shard.num_states
        if len(mine):
            done, differ = _replay_kinds(shard, mine, kinds, invalid_greedy)
            replayed, mismatched = replayed + done, mismatched + differ
    for entry in kinds.values():
        g = entry["greedy"]
        entry["excess"] = g["invalid"] - rate * g["picks"]
        entry["p_above_rate"] = binomial_tail(g["invalid"], g["picks"], rate)
    total = sum(max(e["excess"], 0.0) for e in kinds.values())
    ranked = sorted(kinds, key=lambda k: -kinds[k]["excess"])
    top = ranked[:2]
    share = sum(max(kinds[k]["excess"], 0.0) for k in top) / total if total > 0 else float("nan")
    concentrated = bool(total > 0 and share >= 0.6 and all(kinds[k]["p_above_rate"] < 0.05 for k in top))
    picked = sum(r["picked_left"] for r in invalid_greedy)
    return {"series": series, "all_states": all_states, "states": int(len(states)), "replayed": replayed,
            "mismatched": mismatched, "rate": rate,
            "greedy": {"picks": sum(e["greedy"]["picks"] for e in kinds.values()),
                       "invalid": sum(e["greedy"]["invalid"] for e in kinds.values())},
            "kinds": {k: kinds[k] for k in ranked}, "positive_excess": total, "top_two": top,
            "top_two_share": share, "reading": "concentrated" if concentrated else "spread",
            "invalid_greedy": invalid_greedy,
            "picked_object_left": {"picks": len(invalid_greedy), "picked_left": picked,
                                   "other_left": sum(bool(set(r["left_uids"]) - {r["uid"]}) for r in invalid_greedy),
                                   "nothing_left": sum(not r["left_uids"] for r in invalid_greedy)}}


def binomial_tail(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p)."""
    from math import comb

    return float(min(1.0, sum(comb(n, i) * p**i * (1 - p) ** (n - i) for i in range(k, n + 1))))


def _replay_kinds(shard: Any, mine: np.ndarray, kinds: dict[str, dict[str, Any]],
                  invalid_greedy: list[dict[str, Any]]) -> tuple[int, int]:
    """`kinds_report` on one shard's states ``mine`` (local indices): tallies into ``kinds``, a record per invalid
    greedy pick into ``invalid_greedy``; returns (states replayed, states whose observation differed)."""
    from shelf_env.privileged import dataset

    a = shard.arrays
    greedy_source = dataset.SOURCES.index("greedy")
    env = dataset.replay_env(shard)
    base: Any = env.unwrapped
    replayed = differ = 0
    try:
        for i, ep in enumerate(shard.meta["episodes"]):
            here = [int(s) for s in mine if a["state_episode"][s] == i]
            if not here:
                continue
            base.set_num_objects(ep["num_objects"])
            obs, _ = env.reset(seed=ep["reset_seed"])
            t = 0
            for s in sorted(here, key=lambda s: int(a["state_step"][s])):
                while t < int(a["state_step"][s]):
                    obs, *_ = env.step(ep["actions"][t])
                    t += 1
                replayed += 1
                if not np.array_equal(obs, a["obs"][s]):
                    differ += 1
                    continue
                for kind in {o.spec.kind for o in base.world.objects}:
                    _kind_entry(kinds, kind)["states"] += 1
                labels = np.flatnonzero(a["label_state"] == s)
                greedy = {int(a["label_action"][k]) for k in labels if a["label_source"][k] == greedy_source}
                seen: set[tuple[int, bool]] = set()
                for k in labels:
                    action, is_greedy = int(a["label_action"][k]), bool(a["label_source"][k] == greedy_source)
                    if (base.decode_action(action)[0] != "pick" or (not is_greedy and action in greedy)
                            or (action, is_greedy) in seen):
                        continue
                    seen.add((action, is_greedy))
                    uid, kind = picked_object(base, action)
                    invalid = not bool(a["label_valid"][k])
                    tally = _kind_entry(kinds, kind)["greedy" if is_greedy else "others"]
                    tally["picks"] += 1
                    tally["invalid"] += int(invalid)
                    if is_greedy and invalid:
                        copy = _step_in_copy(env, action)
                        invalid_greedy.append({"shard": shard.path.name, "state": s, "num_objects": ep["num_objects"],
                                               "kind": kind, "uid": uid, **copy,
                                               "picked_left": uid in copy["left_uids"]})
    finally:
        env.close()
    return replayed, differ


def picked_object(env: Any, action: int) -> tuple[int, str]:
    """The uid and kind of the object a pick ``action`` meets in ``env``'s current state: the object under its cell
    in the env's observed semantic map (what the camera shows there, which the cup meets first); ``(-1, "none")``
    where the cell shows no object. ValueError for an action that is not a pick."""
    base = env.unwrapped
    name, row, col = base.decode_action(action)
    if name != "pick":
        raise ValueError(f"action {action} is not a pick (it is a {name})")
    uid = int(base._observed_semantic()[0][row, col])
    kind = {o.uid: o.spec.kind for o in base.world.objects}.get(uid)
    return (uid, kind) if kind is not None else (-1, "none")


def _kind_entry(kinds: dict[str, dict[str, Any]], kind: str) -> dict[str, Any]:
    return kinds.setdefault(kind, {"states": 0, "greedy": {"picks": 0, "invalid": 0},
                                   "others": {"picks": 0, "invalid": 0}})


def _step_in_copy(env: Any, action: int) -> dict[str, Any]:
    """``action`` stepped in a forked copy of ``env`` (`shelf_env.privileged.lookahead.in_fork`): the uids and
    kinds of the objects that left the cabinet, the kinds of those inside left not at rest, and the step's flags."""
    from shelf_env.privileged.lookahead import in_fork

    def work(base: Any) -> dict[str, Any]:
        before = {o.uid: o.spec.kind for o in base.world.objects}
        outcome = base.step_outcome(int(action))
        inside = {o.uid for o in base.world.objects}  # the env removes what left the cabinet
        left = sorted(uid for uid in before if uid not in inside)
        return {"left_uids": left, "left": [before[uid] for uid in left], "fell": outcome["fell"],
                "not_at_rest": [o.spec.kind for o, rest in zip(base.world.objects, base.world.at_rest()) if not rest]}

    return in_fork(env, work, f"stepping action {action}")


def carry_view(data: pathlib.Path, series: str, kinds: dict[str, Any],
               risk: GeometryRisk | None = None) -> dict[str, Any]:
    """Whether the camera saw each greedy pick's carry as clear (`shelf_env.conditions.safe_picks.carry_clear` on the
    stored observation's blobs and heights, as `restrict_to_clear_carries` reads them), by what the pick did in the
    `kinds_report` ``kinds`` of every state of ``series`` in ``data``: ``valid``, ``bystander`` (another object
    left the cabinet), ``picked`` (only the picked object left) or ``moving`` (nothing left, an object kept moving);
    ``tall_blocked`` counts those whose carry is blocked by an object taller than any training object
    (`research.tall_guard.tall_blocked_cells`).
    With ``risk`` (an exported `GeometryRisk`, such as the shipped filter's) also each group's mean risk and the AUC
    of the risk for each invalid group against the valid picks. A report with states that did not replay is refused:
    its invalid picks' outcomes are unknown."""
    from research.tall_guard import tall_blocked_cells
    from shelf_env.baselines.heuristics import ObservationView
    from shelf_env.camera.heightmap import observed_height
    from shelf_env.conditions.safe_picks import carry_clear
    from shelf_env.privileged.dataset import SOURCES

    if kinds.get("mismatched", 0) or not kinds.get("all_states"):
        raise ValueError("carry_view needs a kinds report of every state, each replayed exactly (all_states, "
                         f"mismatched 0); got all_states={kinds.get('all_states')}, "
                         f"mismatched={kinds.get('mismatched')}")
    outcome = {(r["shard"], int(r["state"])): ("bystander" if set(r["left_uids"]) - {r["uid"]} else
                                              "picked" if r["picked_left"] else "moving")
               for r in kinds["invalid_greedy"]}
    groups = {name: {"picks": 0, "clear": 0, "tall_blocked": 0} for name in ("valid", "bystander", "picked", "moving")}
    risks: dict[str, list[float]] = {}
    greedy_source = SOURCES.index("greedy")
    for shard in series_states(data, 0.2, None, None, None, series, all_states=True)[0]:
        a = shard.arrays
        width, cells = a["obs"].shape[-1], int(np.prod(a["obs"].shape[-2:]))
        pick = list(shard.meta["layout"]["map_names"]).index("pick")
        for k in np.flatnonzero((a["label_source"] == greedy_source) & (a["label_action"] // cells == pick)):
            state, (row, col) = int(a["label_state"][k]), divmod(int(a["label_action"][k]) % cells, width)
            key = (shard.path.name, state)
            if not a["label_valid"][k] and key not in outcome:
                raise ValueError(f"{shard.path.name} state {state}: an invalid greedy pick the kinds report lacks")
            obs = a["obs"][state]
            view = ObservationView.from_observation(obs, 0)
            clear = carry_clear(view.blob, observed_height(obs), shard.meta["layout"]["pixel_size"])
            name = "valid" if a["label_valid"][k] else outcome[key]
            groups[name]["picks"] += 1
            groups[name]["clear"] += int(clear[row, col])
            groups[name]["tall_blocked"] += int(tall_blocked_cells(obs, view=view)[row, col])
            if risk is not None:
                x = geometry_features(obs, np.array([row * width + col]), risk.blockers)
                risks.setdefault(name, []).append(float(risk.model.risk(x)[0]))
    out: dict[str, Any] = {"series": series, "groups": groups}
    if risk is not None:
        valid = np.array(risks.get("valid", []))
        out["risk"] = {name: {"mean": float(np.mean(r)),
                              "auc_against_valid": None if name == "valid" else fall_risk.auc(
                                  np.r_[np.zeros(len(valid)), np.ones(len(r))], np.r_[valid, r])}
                       for name, r in risks.items()}
    return out


def height_labels(edges: Sequence[float] = HEIGHT_EDGES) -> list[str]:
    """Names of the height bands of ``edges`` in centimetres: ``["<6", "6-9", "9-12", ">=12"]``."""
    cm = [f"{100 * e:g}" for e in edges]
    return [f"<{cm[0]}", *(f"{a}-{b}" for a, b in zip(cm, cm[1:])), f">={cm[-1]}"]


def probe(out: pathlib.Path, hours: float, model: str, series: int = 90, object_set: str = "ycb") -> int:
    """A probe set of ``object_set`` scenes for measuring fall models on objects the teacher dataset never holds:
    `shelf_env.privileged.dataset.collect` (labels and probes unchanged) driven by ``model`` as it plays (explore
    1.0) into ``out``, which must not hold shards of another object set (so that it never enters a training-object
    dataset). Resumable as the collector is; returns the shards written."""
    from shelf_env.privileged import dataset

    if object_set == "train":
        raise ValueError("a probe is for objects the teacher dataset does not hold; the dataset collects 'train'")
    if dataset.shard_files(out):
        other = {str(s.meta.get("object_set")) for s in dataset.load_dataset(out)} - {object_set}
        if other:
            raise ValueError(f"{out} holds shards of object set(s) {sorted(other)}; a {object_set} probe goes in a "
                             "folder of its own")
    out.mkdir(parents=True, exist_ok=True)
    return dataset.collect(out, series=series, hours=hours, model_path=model, explore=1.0, object_set=object_set)


def _without(split: fall_risk.Split, part: fall_risk.Split) -> fall_risk.Split:
    """``split``'s labels that are not in ``part`` (the same states; a label is its state and cell)."""
    key = split.state.numpy() * 10**7 + split.cell.numpy()
    drop = np.isin(key, part.state.numpy() * 10**7 + part.cell.numpy())
    keep = th.as_tensor(~drop)
    return fall_risk.Split(split.obs, split.state[keep], split.cell[keep], split.label[keep], split.objects, None)


def fresh_split(data: pathlib.Path, used: str | None, fresh: str) -> fall_risk.Split:
    """The pick labels of every state of the shards ``fresh`` selects (`select_shards`' spec) that ``used``
    (the fall model's ``--max-shards``) does not: a test set no fall model trained on."""
    from shelf_env.privileged import dataset

    return _whole(_fresh_shards(dataset.load_dataset(data), used, fresh))


def _fresh_shards(shards: list[Any], used: str | None, fresh: str) -> list[Any]:
    from shelf_env.privileged import dataset

    taken = {s.path.name for s in dataset.select_shards(shards, used)}
    chosen = [s for s in dataset.select_shards(shards, fresh) if s.path.name not in taken]
    if not chosen:
        raise ValueError(f"--fresh {fresh} selects no shard that {used} leaves out")
    return chosen


def _whole(shards: list[Any]) -> fall_risk.Split:
    return fall_risk.teacher_split(shards, np.arange(sum(s.num_states for s in shards)))


def build(sets: Sets, out: pathlib.Path, blockers: bool = False) -> dict[str, Any]:
    """The features of ``sets`` (the test set's too, where it has one), saved atomically to ``out`` (``.npz``)."""
    train, val = sets.train, sets.val
    arrays = {"train_x": split_features(train, blockers), "train_y": train.label.numpy().astype(np.int8),
              "val_x": split_features(val, blockers), "val_y": val.label.numpy().astype(np.int8),
              "val_state": val.state.numpy(), "val_scene": sets.val_scene[val.state.numpy()],
              "names": np.array(feature_names(blockers))}
    if sets.test is not None:
        arrays |= {"test_x": split_features(sets.test, blockers), "test_y": sets.test.label.numpy().astype(np.int8)}

    def save(path: pathlib.Path) -> None:
        with open(path, "wb") as f:
            np.savez_compressed(f, **arrays)

    write_atomically(out, save)
    counts = {f"{k}_labels": len(arrays[f"{k}_y"]) for k in ("train", "val", "test") if f"{k}_y" in arrays}
    return counts | {f"{k}_invalid": float(arrays[f"{k}_y"].mean()) for k in ("train", "val", "test")
                     if f"{k}_y" in arrays}


def load_features(path: pathlib.Path) -> tuple[Any, tuple[str, ...]]:
    """A `build` file (its arrays, lazily) and its feature names; a `ValueError` if it holds another feature set."""
    z = np.load(path, allow_pickle=False)
    names = tuple(str(n) for n in z["names"])
    if names not in (feature_names(False), feature_names(True)):
        raise ValueError(f"{path} holds other features ({list(names)}); rebuild it with `features`")
    return z, names


def fit(train_x: np.ndarray, train_y: np.ndarray, val_x: np.ndarray, val_y: np.ndarray, hidden: int = 64,
        epochs: int = 20, batch: int = 256, lr: float = 1e-3, seed: int = 0) -> tuple[FeatureModel, dict[str, Any]]:
    """A `FeatureModel` fitted by binary cross-entropy (Adam); the weights of the epoch with the best
    held-out AUC (as the fall model's curve reports), and the per-epoch AUCs."""
    if len(train_x) != len(train_y) or len(val_x) != len(val_y) or len(train_x) == 0:
        raise ValueError(f"need matching, non-empty features and labels, got {len(train_x)}/{len(train_y)} "
                         f"training and {len(val_x)}/{len(val_y)} held-out")
    th.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = FeatureModel(train_x.mean(axis=0), train_x.std(axis=0), hidden)
    opt = th.optim.Adam(model.parameters(), lr=lr)
    x, y = th.as_tensor(train_x, dtype=th.float32), th.as_tensor(train_y, dtype=th.float32)
    history, best, best_state = [], -1.0, None
    for _ in range(epochs):
        _epoch(model, opt, x, y, rng, batch)
        score = fall_risk.auc(val_y, model.risk(val_x))
        history.append(score)
        if score > best:
            best, best_state = score, {k: v.clone() for k, v in model.state_dict().items()}
    assert best_state is not None
    model.load_state_dict(best_state)
    return model, {"val_auc": best, "best_epoch": int(np.argmax(history)) + 1, "history": history}


def feature_aucs(train_x: np.ndarray, train_y: np.ndarray, val_x: np.ndarray, val_y: np.ndarray,
                 names: tuple[str, ...] = FEATURES) -> dict[str, Any]:
    """Each feature's own held-out AUC as a risk score, its direction (+1: larger is riskier) read from the
    training labels."""
    out = {}
    for j, name in enumerate(names):
        sign = 1.0 if fall_risk.auc(train_y, train_x[:, j]) >= 0.5 else -1.0
        out[name] = {"sign": sign, "val_auc": fall_risk.auc(val_y, sign * val_x[:, j])}
    return out


def scene_folds(scenes: np.ndarray) -> np.ndarray:
    """0/1 per entry: the scenes in sorted order alternate between the two folds."""
    unique = np.unique(scenes)
    return (np.searchsorted(unique, scenes) % 2).astype(np.int64)


def twofold(x: np.ndarray, y: np.ndarray, scenes: np.ndarray, hidden: int = 64, epochs: int = 20,
            seed: int = 0) -> np.ndarray:
    """Each label's risk from a `FeatureModel` fitted on the other fold's scenes (`scene_folds`), a fixed
    ``epochs`` (no epoch is chosen on the scored fold)."""
    fold = scene_folds(scenes)
    out = np.zeros(len(y), np.float64)
    for f in (0, 1):
        fit_on, score_on = fold != f, fold == f
        if not fit_on.any() or not score_on.any():
            raise ValueError("two-fold needs held-out labels from at least two scenes")
        th.manual_seed(seed)  # each fold's start from the seed, not from whatever ran before
        model = FeatureModel(x[fit_on].mean(axis=0), x[fit_on].std(axis=0), hidden)
        _train_fixed(model, x[fit_on], y[fit_on], epochs, seed)
        out[score_on] = model.risk(x[score_on])
    return out


def _train_fixed(model: FeatureModel, x_np: np.ndarray, y_np: np.ndarray, epochs: int, seed: int,
                 batch: int = 256, lr: float = 1e-3) -> None:
    rng = np.random.default_rng(seed)
    opt = th.optim.Adam(model.parameters(), lr=lr)
    x, y = th.as_tensor(x_np, dtype=th.float32), th.as_tensor(y_np, dtype=th.float32)
    for _ in range(epochs):
        _epoch(model, opt, x, y, rng, batch)


def _epoch(model: FeatureModel, opt: th.optim.Optimizer, x: th.Tensor, y: th.Tensor, rng: np.random.Generator,
           batch: int) -> None:
    """One pass of binary cross-entropy over ``x``, ``y`` in a random order of ``batch``-sized steps."""
    model.train()
    order = th.as_tensor(rng.permutation(len(x)))
    for start in range(0, len(x), batch):
        sel = order[start:start + batch]
        loss = th.nn.functional.binary_cross_entropy_with_logits(model(x[sel]), y[sel])
        opt.zero_grad()
        loss.backward()
        opt.step()
    model.eval()


def logit(p: np.ndarray) -> np.ndarray:
    p = np.clip(np.asarray(p, np.float64), 1e-6, 1 - 1e-6)
    return np.log(p / (1 - p))


def ensemble(*risks: np.ndarray) -> np.ndarray:
    """The risks' logits averaged (equal weights, nothing fitted), as a probability."""
    return 1 / (1 + np.exp(-np.mean([logit(r) for r in risks], axis=0)))


def report(features: pathlib.Path, fcn_risk: np.ndarray | None, epochs: int = 20, seed: int = 0,
           fcn_test_risk: np.ndarray | None = None
           ) -> tuple[dict[str, Any], dict[str, FeatureModel], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The fit's report on a `build` file: the logistic and MLP models' held-out AUCs, each feature's own,
    and with ``fcn_risk`` (the fall model's held-out risk, in the file's held-out label order) its AUC, the
    two-fold AUCs of the features alone and joined to it, and the `ensemble` of it and the MLP. Where the file
    holds a test set (`build`'s ``fresh``), ``test``: the same models' AUCs on it (the fall model's with
    ``fcn_test_risk``). Also the two models, and the held-out and test risks (``mlp``, ``logistic``, ``joint``,
    ``ensemble``, ...)."""
    z, names = load_features(features)
    tx, ty, vx, vy = z["train_x"], z["train_y"].astype(np.float64), z["val_x"], z["val_y"].astype(np.float64)
    out: dict[str, Any] = {"features_set": "blockers" if names == feature_names(True) else "named",
                           "train_labels": len(ty), "val_labels": len(vy), "val_invalid": float(vy.mean()),
                           "epochs": epochs}
    models, risks, test = {}, {}, {}
    has_test = "test_x" in z.files
    for name, hidden in (("logistic", 0), ("mlp", 64)):
        models[name], hist = fit(tx, ty, vx, vy, hidden=hidden, epochs=epochs, seed=seed)
        out[name] = hist
        risks[name] = models[name].risk(vx)
        if has_test:
            test[name] = models[name].risk(z["test_x"])
    out["features"] = feature_aucs(tx, ty, vx, vy, names)
    if fcn_risk is not None:
        if len(fcn_risk) != len(vy):
            raise ValueError(f"the fall model's risk has {len(fcn_risk)} entries for {len(vy)} held-out labels")
        scenes = z["val_scene"]
        risks["features_twofold"] = twofold(vx, vy, scenes, epochs=epochs, seed=seed)
        joined = np.column_stack([vx, logit(fcn_risk)])
        risks["joint"] = twofold(joined, vy, scenes, epochs=epochs, seed=seed)
        risks["joint_logistic"] = twofold(joined, vy, scenes, hidden=0, epochs=epochs, seed=seed)
        risks["ensemble"] = ensemble(fcn_risk, risks["mlp"])  # no fit on held-out labels at all
        out["twofold"] = {"scenes": int(len(np.unique(scenes))), "fcn": fall_risk.auc(vy, fcn_risk),
                          "features": fall_risk.auc(vy, risks["features_twofold"]),
                          "joint": fall_risk.auc(vy, risks["joint"]),
                          "joint_logistic": fall_risk.auc(vy, risks["joint_logistic"])}
        out["ensemble"] = fall_risk.auc(vy, risks["ensemble"])
    if has_test:
        sy = z["test_y"].astype(np.float64)
        if fcn_test_risk is not None:
            if len(fcn_test_risk) != len(sy):
                raise ValueError(f"the fall model's test risk has {len(fcn_test_risk)} entries for {len(sy)} labels")
            test["fcn"] = fcn_test_risk
            test["ensemble"] = ensemble(fcn_test_risk, test["mlp"])
        out["test"] = {"labels": len(sy), "invalid": float(sy.mean()),
                       **{k: fall_risk.auc(sy, r) for k, r in test.items()}}
    return out, models, risks, test


def compare_risk(features: pathlib.Path, risk_path: pathlib.Path, models: dict[str, FeatureModel]
                 ) -> dict[str, Any]:
    """An exported `GeometryRisk` (``risk_path``, e.g. the shipped filter's) beside a refit's models on the same
    labels of a `build` file: each one's AUC on validation and test, and at the exported risk's threshold the
    share of pick labels masked and the invalid share of those allowed (a refit's threshold means what the
    exported one's did only if these match)."""
    z, names = load_features(features)
    exported = GeometryRisk.load(risk_path)
    if len(exported.model.mean) != len(names) or exported.blockers != (names == feature_names(True)):
        raise ValueError(f"{risk_path} reads {len(exported.model.mean)} features, {features} holds {len(names)}")
    scored = {"exported": exported.model, **models}
    out: dict[str, Any] = {"path": str(risk_path), "threshold": exported.threshold}
    for part in ("val", "test"):
        if f"{part}_x" not in z.files:
            continue
        x, y = z[f"{part}_x"], z[f"{part}_y"].astype(bool)
        for name, model in scored.items():
            risk = model.risk(x)
            allowed = risk < exported.threshold
            out.setdefault(name, {})[part] = {
                "auc": fall_risk.auc(y.astype(np.float64), risk), "masked": float(1 - allowed.mean()),
                "allowed_invalid": float(y[allowed].mean()) if allowed.any() else float("nan")}
    return out


def reading(result: dict[str, Any], bar: float = 0.886) -> str:
    """The plan's reading of a `report` (docs/experiments/fall-geometry.md)."""
    f = result["mlp"]["val_auc"]
    j = result.get("twofold", {}).get("joint", float("nan"))
    if f >= bar:
        return "features"
    if j >= bar:
        return "joint"
    if result.get("ensemble", float("nan")) >= bar:  # added after the first numbers (the page says so)
        return "ensemble"
    return "neither"


def fcn_risks(sets: Sets, model_path: pathlib.Path) -> tuple[np.ndarray, np.ndarray | None]:
    """The fall model's risk at each validation pick label of ``sets``, and at each test label where it has a
    test set (the `build` file's orders)."""
    model = fall_risk.FallRiskModel.load(model_path)
    test = None if sets.test is None else fall_risk.scores(model, sets.test).astype(np.float64)
    return fall_risk.scores(model, sets.val).astype(np.float64), test


def offline(checkpoint: str, split: fall_risk.Split, scored: dict[str, np.ndarray]) -> dict[str, Any]:
    """`research.fall_risk.penalty_report` of each risk in ``scored`` (at ``split``'s labels)."""
    if split.sorted_change is None:
        raise ValueError("the offline check needs a teacher dataset's change in sorted objects")
    values, groups = fall_risk.pick_values(checkpoint, split)
    return {"checkpoint": checkpoint, **fall_risk.penalty_report(split.label.numpy(), split.sorted_change, values,
                                                                 scored, groups)}


#: `feature_channels`' quantisation: uint8 steps per standard deviation around 128 (clipped at +-4 sd).
CHANNEL_STEPS = 32


def feature_channels(obs: np.ndarray, mean: np.ndarray, std: np.ndarray, blockers: bool = True) -> np.ndarray:
    """(K, H, W) uint8: `geometry_features` at every cell of ``obs``, standardised with ``mean`` and ``std``
    (the training labels'), ``CHANNEL_STEPS`` steps per standard deviation around 128."""
    rows, cols = np.asarray(obs).shape[1:]
    x = geometry_features(obs, np.arange(rows * cols), blockers)
    if x.shape[1] != len(mean) or len(mean) != len(std):
        raise ValueError(f"{x.shape[1]} features, but a normalisation of {len(mean)} means and {len(std)} spreads")
    z = (x - mean) / np.where(std > 0, std, 1.0)
    q = np.clip(np.round(z * CHANNEL_STEPS + 128), 0, 255).astype(np.uint8)
    return q.T.reshape(-1, rows, cols)


def with_channels(split: fall_risk.Split, mean: np.ndarray, std: np.ndarray, blockers: bool = True
                  ) -> fall_risk.Split:
    """``split`` with `feature_channels` appended to every observation (labels unchanged)."""
    obs = split.obs.numpy()
    extra = np.stack([feature_channels(o, mean, std, blockers) for o in obs]) if len(obs) else np.zeros(
        (0, len(mean), *obs.shape[2:]), np.uint8)
    return dataclasses.replace(split, obs=th.as_tensor(np.concatenate([obs, extra], axis=1)))


def channels_run(sets: Sets, features: pathlib.Path, out: pathlib.Path, checkpoint: str | None, epochs: int = 8,
                 fall_model: pathlib.Path | None = None, info: dict[str, Any] | None = None) -> dict[str, Any]:
    """Round three (docs/experiments/fall-geometry.md): the fall model's recipe from scratch on the camera
    observation plus `feature_channels` (normalised with the ``features`` file's training features), saved to
    ``out`` (``.pt``, with ``info`` about the data); its AUC on the validation split and the test set, with the
    offline check of ``checkpoint``'s choice on both."""
    z, names = load_features(features)
    blockers = names == feature_names(True)
    mean, std = z["train_x"].mean(axis=0), z["train_x"].std(axis=0)
    val = sets.val
    wide_train, wide_val = with_channels(sets.train, mean, std, blockers), with_channels(val, mean, std, blockers)
    model, history, best = fall_risk.fit_fall_risk(wide_train, wide_val, init=None, epochs=epochs)
    del wide_train
    model.save(out, {**(info or {}), "obs_shape": list(wide_val.obs.shape[1:]), "features": list(names),
                     "mean": mean.tolist(), "std": std.tolist(), "channel_steps": CHANNEL_STEPS, "epochs": epochs,
                     "best_epoch": best, "history": history})
    result: dict[str, Any] = {"model": str(out), "best_epoch": best, "history": history,
                              "val_auc": fall_risk.auc(val.label.numpy(), fall_risk.scores(model, wide_val))}
    sets_ = {"val": (val, wide_val)}
    if sets.test is not None:
        sets_["test"] = (sets.test, with_channels(sets.test, mean, std, blockers))
        result["test_auc"] = fall_risk.auc(sets.test.label.numpy(), fall_risk.scores(model, sets_["test"][1]))
    reference = fall_risk.FallRiskModel.load(fall_model) if fall_model is not None else None
    for name, (plain, wide) in sets_.items():
        risks = {"channels": fall_risk.scores(model, wide).astype(np.float64)}
        if reference is not None:
            risks["fcn"] = fall_risk.scores(reference, plain).astype(np.float64)
            result[f"{name}_fcn_auc"] = fall_risk.auc(plain.label.numpy(), risks["fcn"])
        if checkpoint is not None:
            result[f"{name}_offline"] = offline(checkpoint, plain, risks)
    return result


def export(models: pathlib.Path, name: str, features: pathlib.Path, threshold: float, obs_shape: tuple[int, ...],
           out: pathlib.Path) -> GeometryRisk:
    """The ``name`` model of a `fit` run's ``.models.pt`` as a `GeometryRisk` at ``threshold``, saved to ``out``
    (the feature set read from the `fit` run's ``features`` file)."""
    _, names = load_features(features)
    weights = th.load(models, map_location="cpu", weights_only=True)
    if name not in weights:
        raise ValueError(f"{models} holds the models {sorted(weights)}, not {name!r}")
    state = weights[name]
    hidden = 0 if "net.weight" in state else int(state["net.0.weight"].shape[0])
    model = FeatureModel(np.zeros(len(names)), np.ones(len(names)), hidden)
    model.load_state_dict(state)
    model.eval()
    risk = GeometryRisk(model, names == feature_names(True), threshold, obs_shape)
    risk.save(out)
    return risk


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.fall_geometry", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name, text in (("features", "the named features of the fall model's split (.npz)"),
                       ("fit", "the feature models, each feature's AUC, and the features joined to the fall model"),
                       ("channels", "the fall model from scratch with the features as input channels")):
        p = sub.add_parser(name, help=text)
        p.add_argument("--data", type=pathlib.Path, required=True)
        p.add_argument("--max-shards", default=None)
        p.add_argument("--val-fraction", type=float, default=0.2)
        p.add_argument("--fresh", default=None,
                       help="a test set: the shards this --max-shards spec selects that --max-shards leaves out")
        p.add_argument("--fresh-after", default=None,
                       help="the shards the test set comes after (a --max-shards spec; default --max-shards): "
                            "--fresh's shards that it leaves out are the test set, and they leave the split")
        p.add_argument("--extra-data", type=pathlib.Path, action="append", default=[],
                       help="a folder whose every shard joins the pool (another object set's series), repeatable")
        p.add_argument("--out", type=pathlib.Path, required=True)
        if name == "features":
            p.add_argument("--blockers", action="store_true", help="round two's blocker features too")
        elif name == "channels":
            p.add_argument("--features", type=pathlib.Path, required=True,
                           help="the `features` file (its set; its training features normalise the channels)")
            p.add_argument("--fall-model", type=pathlib.Path, default=None, help="the fall model to compare (.pt)")
            p.add_argument("--epochs", type=int, default=8)
            p.add_argument("--checkpoint", default=None, help="with it, the offline check on each set")
            p.add_argument("--report", type=pathlib.Path, required=True, help="the report (JSON)")
        else:
            p.add_argument("--features", type=pathlib.Path, required=True, help="the `features` file")
            p.add_argument("--fall-model", type=pathlib.Path, default=None, help="the fall model to join (.pt)")
            p.add_argument("--epochs", type=int, default=20)
            p.add_argument("--checkpoint", default=None,
                           help="with it, the offline check (research.fall_risk.penalty_report) of each risk")
            p.add_argument("--compare", type=pathlib.Path, default=None,
                           help="an exported geometry risk (.geometry_risk.pt) scored beside the fit (compare_risk)")
    g = sub.add_parser("greedy", help="exported risks on the picks a driving policy made (greedy_report)")
    k = sub.add_parser("kinds", help="the kinds of object the picks took and that fell, by replay (kinds_report)")
    for q in (g, k):
        q.add_argument("--data", type=pathlib.Path, required=True)
        q.add_argument("--max-shards", default=None)
        q.add_argument("--val-fraction", type=float, default=0.2)
        q.add_argument("--fresh", default=None, help="the test set left out of the split (as `features`)")
        q.add_argument("--fresh-after", default=None, help="as `features`")
        q.add_argument("--extra-data", type=pathlib.Path, action="append", default=[], help="as `features`")
        q.add_argument("--series", required=True, help="the series whose greedy picks are read (s05; s90,s91)")
        q.add_argument("--all-states", action="store_true",
                       help="every state, not the validation split (a probe set)")
        q.add_argument("--out", type=pathlib.Path, required=True, help="the report (JSON)")
    g.add_argument("--risk", action="append", required=True, metavar="NAME=PATH",
                   help="an exported geometry risk (.geometry_risk.pt), repeatable")
    k.add_argument("--rate", type=float, default=0.053,
                   help="the greedy picks' invalid share a kind's excess is counted over (training objects': 0.053)")
    c = sub.add_parser("carry", help="whether the camera saw each greedy pick's carry as clear, by its outcome")
    c.add_argument("--data", type=pathlib.Path, required=True)
    c.add_argument("--series", required=True)
    c.add_argument("--kinds", type=pathlib.Path, required=True, help="the `kinds` report of every state (JSON)")
    c.add_argument("--risk", type=pathlib.Path, default=None,
                   help="an exported geometry risk (.geometry_risk.pt) scored on the same picks")
    c.add_argument("--out", type=pathlib.Path, required=True, help="the report (JSON)")
    pr = sub.add_parser("probe", help="a probe set of unseen-object scenes for measuring fall models (probe)")
    pr.add_argument("--out", type=pathlib.Path, required=True, help="its own folder (never the teacher dataset)")
    pr.add_argument("--hours", type=float, required=True, help="wall-clock budget; a shard under way is finished")
    pr.add_argument("--model", required=True, help="the driving policy (a checkpoint with its wrappers)")
    pr.add_argument("--series", type=int, default=90)
    pr.add_argument("--object-set", default="ycb")
    e = sub.add_parser("export", help="a fit's model as a GeometryRisk (<stem>.geometry_risk.pt for a filter)")
    e.add_argument("--models", type=pathlib.Path, required=True, help="a fit run's .models.pt")
    e.add_argument("--name", default="mlp", help="which of its models (mlp, logistic)")
    e.add_argument("--features", type=pathlib.Path, required=True, help="the fit run's features file")
    e.add_argument("--threshold", type=float, required=True)
    e.add_argument("--obs-shape", default="4,40,60", help="the observations it judges (C,H,W)")
    e.add_argument("--out", type=pathlib.Path, required=True)
    args = parser.parse_args(argv)
    try:
        if args.command == "export":
            shape = tuple(int(v) for v in args.obs_shape.split(","))
            for path in (args.models, args.features):
                if not path.is_file():
                    raise ValueError(f"{path} does not exist")
            exported = export(args.models, args.name, args.features, args.threshold, shape, args.out)
            print(json.dumps({"out": str(args.out), "threshold": exported.threshold, "hidden": exported.hidden,
                              "blockers": exported.blockers}))
            return 0
        if args.command == "greedy":
            risk_files = {}
            for item in args.risk:
                name, sep, path = item.partition("=")
                if not sep or not name or not path:
                    raise ValueError(f"--risk takes NAME=PATH, got {item!r}")
                if not pathlib.Path(path).is_file():
                    raise ValueError(f"--risk {item}: {path} does not exist")
                risk_files[name] = pathlib.Path(path)
            result = greedy_report(args.data, args.val_fraction, args.max_shards, args.fresh, args.fresh_after,
                                   args.series, risk_files, all_states=args.all_states, extra=args.extra_data)
            write_json_atomically(args.out, result)
            print(json.dumps({k: {n: v[n]["auc"] for n in risk_files} | {"picks": v["picks"], "invalid": v["invalid"]}
                              for k, v in result.items() if k in ("greedy", "others")}))
            return 0
        if args.command == "kinds":
            result = kinds_report(args.data, args.val_fraction, args.max_shards, args.fresh, args.fresh_after,
                                  args.series, args.all_states, args.extra_data, args.rate)
            write_json_atomically(args.out, result)
            print(json.dumps({key: result[key] for key in ("states", "mismatched", "greedy", "top_two",
                                                           "top_two_share", "reading", "picked_object_left")}))
            return 0
        if args.command == "carry":
            if not args.kinds.is_file():
                raise ValueError(f"--kinds {args.kinds} does not exist; make it with `kinds --all-states`")
            if args.risk is not None and not args.risk.is_file():
                raise ValueError(f"--risk {args.risk} does not exist")
            result = carry_view(args.data, args.series, json.loads(args.kinds.read_text()),
                                GeometryRisk.load(args.risk) if args.risk is not None else None)
            write_json_atomically(args.out, result)
            print(json.dumps(result["groups"]))
            return 0
        if args.command == "probe":
            print(json.dumps({"shards_written": probe(args.out, args.hours, args.model, args.series,
                                                      args.object_set)}))
            return 0
        if args.command == "features":
            built = load_sets(args.data, args.val_fraction, args.max_shards, args.fresh, args.fresh_after,
                              args.extra_data)
            print(json.dumps(build(built, args.out, args.blockers)))
            return 0
        if not args.features.is_file():
            raise ValueError(f"{args.features} does not exist; make it with `features`")
        if getattr(args, "compare", None) is not None and not args.compare.is_file():
            raise ValueError(f"--compare {args.compare} does not exist")
        needs_data = args.command == "channels" or args.fall_model is not None or args.checkpoint is not None
        sets = (load_sets(args.data, args.val_fraction, args.max_shards, args.fresh, args.fresh_after,
                          args.extra_data) if needs_data else None)
        if args.command == "channels":
            assert sets is not None
            result = channels_run(sets, args.features, args.out, args.checkpoint, args.epochs, args.fall_model,
                                  {"data": str(args.data), "max_shards": args.max_shards,
                                   "val_fraction": args.val_fraction})
            write_json_atomically(args.report, result)
            print(json.dumps({k: v for k, v in result.items() if k.endswith("auc") or k == "best_epoch"}))
            return 0
        risk, test_risk = (fcn_risks(sets, args.fall_model) if sets is not None and args.fall_model is not None
                           else (None, None))
        result, models, risks, test = report(args.features, risk, args.epochs, fcn_test_risk=test_risk)
        result |= {"max_shards": args.max_shards, "val_fraction": args.val_fraction, "fresh": args.fresh,
                   "fresh_after": args.fresh_after,
                   "fall_model": str(args.fall_model) if args.fall_model else None, "reading": reading(result)}
        if sets is not None and args.checkpoint is not None:
            keep = ("mlp", "joint", "ensemble")
            result["offline"] = offline(args.checkpoint, sets.val, {k: v for k, v in risks.items() if k in keep})
            if test and sets.test is not None:
                result["test_offline"] = offline(args.checkpoint, sets.test,
                                                 {k: v for k, v in test.items() if k in keep + ("fcn",)})
        if args.compare is not None:
            result["compare"] = compare_risk(args.features, args.compare, models)
        write_json_atomically(args.out, result)
        weights = {name: m.state_dict() for name, m in models.items()}
        write_atomically(args.out.with_suffix(".models.pt"), lambda tmp: th.save(weights, tmp))
        brief = {k: result[k] for k in ("train_labels", "val_labels", "reading")}
        brief |= {"mlp": result["mlp"]["val_auc"], "logistic": result["logistic"]["val_auc"],
                  "ensemble": result.get("ensemble"),
                  **{f"twofold_{k}": v for k, v in result.get("twofold", {}).items()},
                  **{f"test_{k}": v for k, v in result.get("test", {}).items()}}
        print(json.dumps(brief))
    except ValueError as err:
        print(f"python -m research.fall_geometry {args.command}: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
