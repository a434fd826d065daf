"""Named fall geometry against the learned fall model (docs/experiments/fall-geometry.md).

Per labelled pick of the teacher dataset, a few quantities a person would name, read from the stored
camera observation only (class colours, the height channel, grey cells, region tints; objects as the
heuristics see them, `object_blobs`): the pick cell on its object, the object's size and height, the
carry corridor to the opening (`shelf_env.conditions.safe_picks`'s geometry), its neighbours, the
occluded cells around it, its class's region and the scene (`FEATURES`). Then:

- `features`: the features of the fall model's split (`research.fall_risk.load_splits`) -> one ``.npz``
  (training and held-out features, labels, and the held-out labels' scenes);
- `fit`: a logistic regression and an MLP on the training features, each feature's own AUC, and the
  from-scratch fall model's risk joined to the features, fitted two-fold by scene on the held-out labels
  (`joint_twofold`) -> a JSON report; ``--offline`` adds the offline check of
  `research.fall_risk.penalty_report` with the feature and joint models' risks.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from typing import Any

import cv2
import numpy as np
import torch as th

from research import fall_risk
from shelf_env import params
from shelf_env.baselines.heuristics import object_blobs, object_classes
from shelf_env.camera.heightmap import OCCLUDED_RGB, REGION_RGB, observed_height
from shelf_env.conditions.safe_picks import Z_CARRY
from shelf_env.files import write_atomically, write_json_atomically

#: The features, in column order (heights in metres, distances in cells of the observation).
FEATURES = (
    "on_object",  # the pick cell is on a visible object
    "cell_height",  # the pick cell's observed height
    "offset_rows",  # (pick row - object's mean row) / its rows' extent (> 0: towards the front)
    "offset_cols",  # |pick col - object's mean col| / its columns' extent
    "edge_distance",  # Chebyshev distance from the pick cell to the nearest cell off the object
    "object_max_height", "object_mean_height", "object_area", "object_rows", "object_cols",
    "object_back_row", "object_front_row",  # rows from the back wall; the front row's distance to the opening
    "wall_distance",  # to the nearer side wall
    "carry_margin_05", "carry_margin_15", "carry_margin_30",  # Z_CARRY - cell height - tallest in the corridor
    "corridor_cells",  # other objects' cells in the 0.5 cm corridor
    "nearest_other",  # distance to the nearest other object's cell
    "tallest_near",  # tallest other object within 3 cm of the object
    "grey_near",  # occluded cells within 1 cm of the object
    "grey_behind",  # occluded cells in the object's columns behind it
    "in_region",  # the object's centre is in its class's region (sorted)
    "region_free",  # share of the class region's cells that are free (its tint shows)
    "region_tallest",  # tallest object in the class region
    "scene_objects",  # visible objects
    "scene_grey",  # share of the map's cells that are occluded
)
#: Widths (metres) the carry corridor is widened by on each side, for ``carry_margin_*``.
CORRIDOR_SIDES = (0.005, 0.015, 0.03)
NEAR_M, GREY_NEAR_M, EDGE_CAP = 0.03, 0.01, 10


def _dilate(mask: np.ndarray, cells: int) -> np.ndarray:
    """``mask`` grown by ``cells`` in the Chebyshev sense."""
    if cells <= 0:
        return mask.copy()
    kernel = np.ones((2 * cells + 1, 2 * cells + 1), np.uint8)
    return cv2.dilate(mask.astype(np.uint8), kernel).astype(bool)


def _tallest_in(height: np.ndarray, where: np.ndarray) -> float:
    return float(height[where].max(initial=0.0))


def geometry_features(obs: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """(K, len(FEATURES)) float32: the features of the picks at flat cells ``cells`` of one observation
    ``obs`` (4, H, W). A pick on no object gets ``on_object`` 0, its cell's height and the scene's
    features, and zeros elsewhere."""
    obs = np.asarray(obs)
    if obs.ndim != 3 or obs.shape[0] != 4:
        raise ValueError(f"need one (4, H, W) observation, got shape {obs.shape}")
    rows, cols = obs.shape[1:]
    cells = np.asarray(cells, np.int64)
    if cells.size and (cells.min() < 0 or cells.max() >= rows * cols):
        raise ValueError(f"cells must lie in 0..{rows * cols - 1}, got {cells.min()}..{cells.max()}")
    pixel = params.CABINET_DEPTH / rows
    height = observed_height(obs)
    blob, klass = object_blobs(obs), object_classes(obs)
    rgb = np.moveaxis(obs[:3], 0, -1)
    grey = (rgb == OCCLUDED_RGB).all(axis=-1)
    objects = blob >= 0
    near, grey_near = int(round(NEAR_M / pixel)), max(int(round(GREY_NEAR_M / pixel)), 1)
    sides = [int(round(s / pixel)) for s in CORRIDOR_SIDES]
    regions = []
    for colour in REGION_RGB:
        rr, cc = np.nonzero((rgb == colour).all(axis=-1))
        regions.append((rr.min(), rr.max(), cc.min(), cc.max()) if rr.size else None)
    scene = (float(blob.max() + 1), float(grey.mean()))
    out = np.zeros((len(cells), len(FEATURES)), np.float32)
    out[:, FEATURES.index("cell_height")] = height.reshape(-1)[cells]
    out[:, -2:] = scene
    own_of = blob.reshape(-1)[cells]
    for b in np.unique(own_of[own_of >= 0]):
        own = blob == b
        rr, cc = np.nonzero(own)
        r0, r1, c0, c1 = int(rr.min()), int(rr.max()), int(cc.min()), int(cc.max())
        others = objects & ~own
        other_height = np.where(others, height, 0.0)
        tallest = [float(other_height[r0:, max(c0 - s, 0):c1 + s + 1].max(initial=0.0)) for s in sides]
        corridor = int(others[r0:, max(c0 - sides[0], 0):c1 + sides[0] + 1].sum())
        if others.any():
            to_other = cv2.distanceTransform((~others).astype(np.uint8), cv2.DIST_C, 3)
            nearest = float(to_other[own].min())
        else:
            nearest = float(max(rows, cols))
        grown = _dilate(own, near)
        halo = _dilate(own, grey_near) & ~own
        behind = np.zeros_like(own)
        behind[:r0, c0:c1 + 1] = True
        k = int(klass[rr[0], cc[0]])
        rect = regions[k]
        if rect is None:
            in_region, free, region_tallest = 0.0, 0.0, 0.0
        else:
            a0, a1, b0, b1 = rect
            in_region = float(a0 <= rr.mean() <= a1 and b0 <= cc.mean() <= b1)
            box = (slice(a0, a1 + 1), slice(b0, b1 + 1))
            free = float((rgb[box] == REGION_RGB[k]).all(axis=-1).mean())
            region_tallest = _tallest_in(height[box], objects[box])
        edge = cv2.distanceTransform(np.pad(own, 1).astype(np.uint8), cv2.DIST_C, 3)[1:-1, 1:-1]
        mine = np.flatnonzero(own_of == b)
        r, c = cells[mine] // cols, cells[mine] % cols
        h_cell = height[r, c]
        per_object = {
            "on_object": 1.0, "object_max_height": float(height[own].max()),
            "object_mean_height": float(height[own].mean()), "object_area": float(own.sum()),
            "object_rows": float(r1 - r0 + 1), "object_cols": float(c1 - c0 + 1), "object_back_row": float(r0),
            "object_front_row": float(rows - 1 - r1), "wall_distance": float(min(c0, cols - 1 - c1)),
            "corridor_cells": float(corridor), "nearest_other": nearest,
            "tallest_near": _tallest_in(height, grown & others), "grey_near": float((halo & grey).sum()),
            "grey_behind": float((behind & grey).sum()), "in_region": in_region, "region_free": free,
            "region_tallest": region_tallest}
        for name, value in per_object.items():
            out[mine, FEATURES.index(name)] = value
        out[mine, FEATURES.index("offset_rows")] = (r - rr.mean()) / (r1 - r0 + 1)
        out[mine, FEATURES.index("offset_cols")] = np.abs(c - cc.mean()) / (c1 - c0 + 1)
        out[mine, FEATURES.index("edge_distance")] = np.minimum(edge[r, c], EDGE_CAP)
        for name, top in zip(("carry_margin_05", "carry_margin_15", "carry_margin_30"), tallest):
            out[mine, FEATURES.index(name)] = Z_CARRY - h_cell - top
    return out


def split_features(split: fall_risk.Split) -> np.ndarray:
    """`geometry_features` of every label of ``split``, in the split's label order."""
    out = np.zeros((len(split.label), len(FEATURES)), np.float32)
    cells, states = split.cell.numpy(), split.state.numpy()
    for index in fall_risk.state_groups(states):
        out[index] = geometry_features(split.obs[int(states[index[0]])].numpy(), cells[index])
    return out


def held_out_scenes(data: pathlib.Path, val_fraction: float, max_shards: str | None) -> np.ndarray:
    """Per held-out state of `research.fall_risk.load_splits`'s split (in its order), a scene number: the
    two-fold split of `joint_twofold` keeps each scene's states together."""
    from shelf_env.privileged import dataset
    from shelf_env.training.distill import select_shards, split_by_scene

    shards = select_shards(dataset.load_dataset(data), max_shards)
    _, val = split_by_scene(shards, val_fraction)
    scene = np.concatenate([shard.arrays["state_episode"].astype(np.int64) + 1000 * k
                            for k, shard in enumerate(shards)])
    return scene[np.array(val)]


def build(data: pathlib.Path, out: pathlib.Path, val_fraction: float, max_shards: str | None) -> dict[str, Any]:
    """The features of the fall model's split, saved atomically to ``out`` (``.npz``)."""
    train, val = fall_risk.load_splits(data, val_fraction, max_shards)
    arrays = {"train_x": split_features(train), "train_y": train.label.numpy().astype(np.int8),
              "val_x": split_features(val), "val_y": val.label.numpy().astype(np.int8),
              "val_state": val.state.numpy(), "val_scene": held_out_scenes(data, val_fraction, max_shards)[
                  val.state.numpy()], "names": np.array(FEATURES)}

    def save(path: pathlib.Path) -> None:
        with open(path, "wb") as f:
            np.savez_compressed(f, **arrays)

    write_atomically(out, save)
    return {"train_labels": len(arrays["train_y"]), "val_labels": len(arrays["val_y"]),
            "train_invalid": float(arrays["train_y"].mean()), "val_invalid": float(arrays["val_y"].mean())}


class FeatureModel(th.nn.Module):
    """Logistic regression (``hidden`` 0) or an MLP (two ``hidden``-wide ReLU layers) on standardised
    features; ``mean`` and ``std`` are the training features'."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, hidden: int = 64) -> None:
        super().__init__()
        self.register_buffer("mean", th.as_tensor(mean, dtype=th.float32))
        self.register_buffer("std", th.as_tensor(np.where(std > 0, std, 1.0), dtype=th.float32))
        n = len(mean)
        self.net = (th.nn.Linear(n, 1) if hidden == 0 else
                    th.nn.Sequential(th.nn.Linear(n, hidden), th.nn.ReLU(), th.nn.Linear(hidden, hidden),
                                     th.nn.ReLU(), th.nn.Linear(hidden, 1)))

    def forward(self, x: th.Tensor) -> th.Tensor:
        return self.net((x - self.mean) / self.std).squeeze(-1)

    def risk(self, x: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return th.sigmoid(self(th.as_tensor(x, dtype=th.float32))).numpy()


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
        model.train()
        order = th.as_tensor(rng.permutation(len(x)))
        for start in range(0, len(x), batch):
            sel = order[start:start + batch]
            loss = th.nn.functional.binary_cross_entropy_with_logits(model(x[sel]), y[sel])
            opt.zero_grad()
            loss.backward()
            opt.step()
        model.eval()
        score = fall_risk.auc(val_y, model.risk(val_x))
        history.append(score)
        if score > best:
            best, best_state = score, {k: v.clone() for k, v in model.state_dict().items()}
    assert best_state is not None
    model.load_state_dict(best_state)
    return model, {"val_auc": best, "best_epoch": int(np.argmax(history)) + 1, "history": history}


def feature_aucs(train_x: np.ndarray, train_y: np.ndarray, val_x: np.ndarray, val_y: np.ndarray) -> dict[str, Any]:
    """Each feature's own held-out AUC as a risk score, its direction (+1: larger is riskier) read from the
    training labels."""
    out = {}
    for j, name in enumerate(FEATURES):
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
        model = FeatureModel(x[fit_on].mean(axis=0), x[fit_on].std(axis=0), hidden)
        _train_fixed(model, x[fit_on], y[fit_on], epochs, seed)
        out[score_on] = model.risk(x[score_on])
    return out


def _train_fixed(model: FeatureModel, x_np: np.ndarray, y_np: np.ndarray, epochs: int, seed: int,
                 batch: int = 256, lr: float = 1e-3) -> None:
    th.manual_seed(seed)
    rng = np.random.default_rng(seed)
    opt = th.optim.Adam(model.parameters(), lr=lr)
    x, y = th.as_tensor(x_np, dtype=th.float32), th.as_tensor(y_np, dtype=th.float32)
    model.train()
    for _ in range(epochs):
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


def report(features: pathlib.Path, fcn_risk: np.ndarray | None, epochs: int = 20,
           seed: int = 0) -> tuple[dict[str, Any], dict[str, FeatureModel], dict[str, np.ndarray]]:
    """The fit's report on a `build` file: the logistic and MLP models' held-out AUCs, each feature's own,
    and with ``fcn_risk`` (the fall model's held-out risk, in the file's held-out label order) its AUC and
    the two-fold AUCs of the features alone and joined to it. Also the two models and the held-out risks
    (``mlp``, ``logistic``, ``joint``)."""
    z = np.load(features, allow_pickle=False)
    if tuple(str(n) for n in z["names"]) != FEATURES:
        raise ValueError(f"{features} holds other features ({list(z['names'])}); rebuild it with `features`")
    tx, ty, vx, vy = z["train_x"], z["train_y"].astype(np.float64), z["val_x"], z["val_y"].astype(np.float64)
    out: dict[str, Any] = {"train_labels": len(ty), "val_labels": len(vy), "val_invalid": float(vy.mean()),
                           "epochs": epochs}
    models, risks = {}, {}
    for name, hidden in (("logistic", 0), ("mlp", 64)):
        models[name], hist = fit(tx, ty, vx, vy, hidden=hidden, epochs=epochs, seed=seed)
        out[name] = hist
        risks[name] = models[name].risk(vx)
    out["features"] = feature_aucs(tx, ty, vx, vy)
    if fcn_risk is not None:
        if len(fcn_risk) != len(vy):
            raise ValueError(f"the fall model's risk has {len(fcn_risk)} entries for {len(vy)} held-out labels")
        scenes = z["val_scene"]
        risks["features_twofold"] = twofold(vx, vy, scenes, epochs=epochs, seed=seed)
        joined = np.column_stack([vx, logit(fcn_risk)])
        risks["joint"] = twofold(joined, vy, scenes, epochs=epochs, seed=seed)
        risks["joint_logistic"] = twofold(joined, vy, scenes, hidden=0, epochs=epochs, seed=seed)
        # no fit on held-out labels at all: the fall model's and the feature MLP's logits, averaged
        risks["ensemble"] = 1 / (1 + np.exp(-(logit(fcn_risk) + logit(risks["mlp"])) / 2))
        out["twofold"] = {"scenes": int(len(np.unique(scenes))), "fcn": fall_risk.auc(vy, fcn_risk),
                          "features": fall_risk.auc(vy, risks["features_twofold"]),
                          "joint": fall_risk.auc(vy, risks["joint"]),
                          "joint_logistic": fall_risk.auc(vy, risks["joint_logistic"])}
        out["ensemble"] = fall_risk.auc(vy, risks["ensemble"])
    return out, models, risks


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


def fcn_held_out_risk(data: pathlib.Path, model_path: pathlib.Path, val_fraction: float,
                      max_shards: str | None) -> np.ndarray:
    """The fall model's risk at each held-out pick label of the split (the `build` file's order)."""
    model = fall_risk.FallRiskModel.load(model_path)
    _, val = fall_risk.load_splits(data, val_fraction, max_shards)
    return fall_risk.scores(model, val).astype(np.float64)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.fall_geometry", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name, text in (("features", "the named features of the fall model's split (.npz)"),
                       ("fit", "the feature models, each feature's AUC, and the features joined to the fall model")):
        p = sub.add_parser(name, help=text)
        p.add_argument("--data", type=pathlib.Path, required=True)
        p.add_argument("--max-shards", default=None)
        p.add_argument("--val-fraction", type=float, default=0.2)
        p.add_argument("--out", type=pathlib.Path, required=True)
        if name == "fit":
            p.add_argument("--features", type=pathlib.Path, required=True, help="the `features` file")
            p.add_argument("--fall-model", type=pathlib.Path, default=None, help="the fall model to join (.pt)")
            p.add_argument("--epochs", type=int, default=20)
            p.add_argument("--checkpoint", default=None,
                           help="with it, the offline check (research.fall_risk.penalty_report) of each risk")
    args = parser.parse_args(argv)
    try:
        if args.command == "features":
            print(json.dumps(build(args.data, args.out, args.val_fraction, args.max_shards)))
            return 0
        if not args.features.is_file():
            raise ValueError(f"{args.features} does not exist; make it with `features`")
        risk = (fcn_held_out_risk(args.data, args.fall_model, args.val_fraction, args.max_shards)
                if args.fall_model is not None else None)
        result, models, risks = report(args.features, risk, args.epochs)
        result |= {"max_shards": args.max_shards, "val_fraction": args.val_fraction,
                   "fall_model": str(args.fall_model) if args.fall_model else None, "reading": reading(result)}
        if args.checkpoint is not None:
            _, val = fall_risk.load_splits(args.data, args.val_fraction, args.max_shards)
            if val.sorted_change is None:
                raise ValueError(f"{args.data} is not a teacher dataset: no change in sorted objects to weigh")
            values, groups = fall_risk.pick_values(args.checkpoint, val)
            scored = {k: v for k, v in risks.items() if k in ("mlp", "joint", "ensemble")}
            result["offline"] = {"checkpoint": args.checkpoint, **fall_risk.penalty_report(
                val.label.numpy(), val.sorted_change, values, scored, groups)}
        write_json_atomically(args.out, result)
        weights = {name: m.state_dict() for name, m in models.items()}
        write_atomically(args.out.with_suffix(".models.pt"), lambda tmp: th.save(weights, tmp))
        brief = {k: result[k] for k in ("train_labels", "val_labels", "reading")}
        brief |= {"mlp": result["mlp"]["val_auc"], "logistic": result["logistic"]["val_auc"],
                  **{f"twofold_{k}": v for k, v in result.get("twofold", {}).items()}}
        print(json.dumps(brief))
    except ValueError as err:
        print(f"python -m research.fall_geometry {args.command}: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
