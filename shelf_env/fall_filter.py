"""A camera-only pick filter: named carry geometry ranks which picks drop an object, and the policy
chooses among the rest.

Most failed episodes of the learned P+S end with an object dragged out of the cabinet by the carry of a
pick (docs/results.md). Which pick does that is mostly geometry a person would name: the object's size
and height, and its straight corridor to the opening under the carry height, with the objects the carry
would hit (the paper's account, §V-d; `shelf_env.conditions.safe_picks` reads the same corridor from the
simulator). This module reads those quantities from the camera observation only (class colours, the
height channel, grey occluded cells, region tints; objects as the heuristics see them, `object_blobs`):

- `geometry_features`: per pick cell, the named quantities (`FEATURES`, and with ``blockers`` the
  `BLOCKER_FEATURES` of what the carry would hit);
- `FeatureModel`: a logistic regression or an MLP on them, fitted to the teacher dataset's pick labels
  (did the pick end the episode invalid; `shelf_env.privileged.dataset`) by ``python -m research.fall_geometry
  fit``;
- `GeometryRisk`: such a model as a per-cell fall-risk map with a threshold, saved as
  ``<checkpoint stem>.geometry_risk.pt`` beside a checkpoint (`geometry_risk_path`);
- `FallFilter`: wraps a policy (SB3's ``predict`` with ``action_masks``) and masks out the pick cells whose
  risk is at or over the threshold; a Q-map policy then takes its best remaining action.

`shelf_env.policies` registers the wrapper: ``"<checkpoint>+geometry-filter"`` plays the checkpoint under
`FallFilter` with the `GeometryRisk` beside it, and ``"+loop-breaker"`` after it adds `sb3_pixeldqn.LoopBreaker`
(its avoided falls otherwise turn into repeated actions). The shipped P+S is played that way
(examples/pretrained/README.md). The filter reads nothing but the observation, so a robot can run it; the labels
it was fitted to came from the simulator, in training only.

Measured (docs/experiments/fall-geometry.md): the MLP ranks the teacher dataset's falls at AUC 0.926 on shards no
choice read (a fall FCN 0.897); at threshold 0.1 on the distilled P+S it cut the greedy fall rate at N = 8 from
13.3 % to 3.4 % on held-out scenes.
"""

from __future__ import annotations

import os
import pathlib
from typing import Any, Protocol

import cv2
import numpy as np
import torch as th

from shelf_env import params
from shelf_env.baselines.heuristics import object_blobs, object_classes
from shelf_env.camera.heightmap import OCCLUDED_RGB, REGION_RGB, observed_height
from shelf_env.conditions.safe_picks import Z_CARRY
from shelf_env.files import write_atomically


class PickRisk(Protocol):
    """What `FallFilter` reads: a per-cell risk map of one observation, the threshold at or over which a pick
    is masked, and ``info`` (``obs_shape``: the observation shape the model was fitted on, or absent)."""

    threshold: float
    info: dict[str, Any]

    def risk(self, obs: np.ndarray) -> np.ndarray: ...

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
#: Round two (``blockers=True``, appended): the *blockers* of a picked object, the other objects with cells in its
#: straight corridor to the opening (its columns, from its back row) whose top is above the carried object's bottom
#: (``Z_CARRY`` - its highest cell), and the front-most of them (zeros where none).
BLOCKER_FEATURES = (
    "blockers",  # how many
    "blocker_gap",  # rows from the object's front row to the nearest blocker cell in the corridor (0: overlapping)
    "blocker_to_opening",  # the front-most blocker's distance to the opening (rows)
    "blocker_rows", "blocker_cols", "blocker_area",  # the front-most blocker's extent and area
    "blocker_in_corridor",  # share of the front-most blocker's columns inside the corridor
    "blockers_area",  # all blockers' area
    "blocker_stopped",  # another object stands between the front-most blocker and the opening, in its columns
    "carry_bottom",  # Z_CARRY - the object's highest cell: the carried object's bottom
)
#: Widths (metres) the carry corridor is widened by on each side, for ``carry_margin_*``, rounded to cells as
#: `shelf_env.conditions.safe_picks` rounds its ``side``: at the dataset's 1 cm cells 0, 2 and 3 cells.
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


def feature_names(blockers: bool = False) -> tuple[str, ...]:
    """The columns of `geometry_features`: round one's, and with ``blockers`` round two's after them."""
    return FEATURES + BLOCKER_FEATURES if blockers else FEATURES


def blocker_features(blob: np.ndarray, height: np.ndarray, b: int) -> dict[str, float]:
    """`BLOCKER_FEATURES` of the object ``b`` (a blob of ``blob``), from the blobs and observed heights."""
    rows = blob.shape[0]
    own = blob == b
    rr, cc = np.nonzero(own)
    r0, r1, c0, c1 = int(rr.min()), int(rr.max()), int(cc.min()), int(cc.max())
    bottom = Z_CARRY - float(height[own].max())
    corridor = np.zeros_like(own)
    corridor[r0:, c0:c1 + 1] = True
    hit = corridor & (blob >= 0) & ~own & (height > bottom)
    out = dict.fromkeys(BLOCKER_FEATURES, 0.0)
    out["carry_bottom"] = bottom
    ids = np.unique(blob[hit])
    if not len(ids):
        return out
    hit_rows = np.nonzero(hit)[0]
    fronts = {int(k): int(np.nonzero(blob == k)[0].max()) for k in ids}
    front = max(fronts, key=lambda k: fronts[k])
    fr_rows, fr_cols = np.nonzero(blob == front)
    cols = np.unique(fr_cols)
    ahead = np.zeros_like(own)
    ahead[fronts[front] + 1:, cols] = True
    out.update({
        "blockers": float(len(ids)), "blocker_gap": float(max(int(hit_rows.min()) - r1 - 1, 0)),
        "blocker_to_opening": float(rows - 1 - fronts[front]),
        "blocker_rows": float(fr_rows.max() - fr_rows.min() + 1), "blocker_cols": float(cols.max() - cols.min() + 1),
        "blocker_area": float(len(fr_rows)), "blocker_in_corridor": float(((cols >= c0) & (cols <= c1)).mean()),
        "blockers_area": float(np.isin(blob, ids).sum()),
        "blocker_stopped": float((ahead & (blob >= 0) & (blob != front) & ~own).any())})
    return out


def geometry_features(obs: np.ndarray, cells: np.ndarray, blockers: bool = False) -> np.ndarray:
    """(K, len(feature_names(blockers))) float32: the features of the picks at flat cells ``cells`` of one
    observation ``obs`` (4, H, W). A pick on no object gets ``on_object`` 0, its cell's height and the
    scene's features, and zeros elsewhere."""
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
    names = feature_names(blockers)
    out = np.zeros((len(cells), len(names)), np.float32)
    out[:, FEATURES.index("cell_height")] = height.reshape(-1)[cells]
    out[:, FEATURES.index("scene_objects")], out[:, FEATURES.index("scene_grey")] = scene
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
        if blockers:
            per_object |= blocker_features(blob, height, int(b))
        for name, value in per_object.items():
            out[mine, names.index(name)] = value
        out[mine, FEATURES.index("offset_rows")] = (r - rr.mean()) / (r1 - r0 + 1)
        out[mine, FEATURES.index("offset_cols")] = np.abs(c - cc.mean()) / (c1 - c0 + 1)
        out[mine, FEATURES.index("edge_distance")] = np.minimum(edge[r, c], EDGE_CAP)
        for name, top in zip(("carry_margin_05", "carry_margin_15", "carry_margin_30"), tallest):
            out[mine, FEATURES.index(name)] = Z_CARRY - h_cell - top
    return out


class FeatureModel(th.nn.Module):
    """Logistic regression (``hidden`` 0) or an MLP (two ``hidden``-wide ReLU layers) on standardised
    features; ``mean`` and ``std`` are the training features'."""

    mean: th.Tensor
    std: th.Tensor

    def __init__(self, mean: np.ndarray, std: np.ndarray, hidden: int = 64) -> None:
        super().__init__()
        self.register_buffer("mean", th.as_tensor(mean, dtype=th.float32))
        self.register_buffer("std", th.as_tensor(np.where(std > 0, std, 1.0), dtype=th.float32))
        n, self.hidden = len(mean), int(hidden)
        self.net = (th.nn.Linear(n, 1) if hidden == 0 else
                    th.nn.Sequential(th.nn.Linear(n, hidden), th.nn.ReLU(), th.nn.Linear(hidden, hidden),
                                     th.nn.ReLU(), th.nn.Linear(hidden, 1)))

    def forward(self, x: th.Tensor) -> th.Tensor:
        return self.net((x - self.mean) / self.std).squeeze(-1)

    def risk(self, x: np.ndarray) -> np.ndarray:
        with th.no_grad():
            return th.sigmoid(self(th.as_tensor(x, dtype=th.float32))).numpy()


class GeometryRisk:
    """A per-cell fall risk from a `FeatureModel`: at every object cell, the model's probability on that
    cell's `geometry_features`; 0 off objects (a pick there holds nothing). A `PickRisk` for `FallFilter`."""

    def __init__(self, model: FeatureModel, blockers: bool, threshold: float, obs_shape: tuple[int, ...]) -> None:
        if not 0 < threshold <= 1:
            raise ValueError(f"threshold must be in (0, 1], got {threshold}")
        self.model, self.blockers, self.threshold = model, bool(blockers), float(threshold)
        self.info: dict[str, Any] = {"obs_shape": list(obs_shape)}

    def risk(self, obs: np.ndarray) -> np.ndarray:
        """(H, W) probability that a pick at each cell ends the episode invalid."""
        obs = np.asarray(obs)
        rows, cols = obs.shape[1:]
        on = np.flatnonzero(object_blobs(obs).reshape(-1) >= 0)
        out = np.zeros(rows * cols)
        if len(on):
            out[on] = self.model.risk(geometry_features(obs, on, self.blockers))
        return out.reshape(rows, cols)

    def save(self, path: str | pathlib.Path) -> None:
        """Weights and settings in one torch file, written atomically."""
        payload = {"state_dict": self.model.state_dict(), "features": len(self.model.mean),
                   "hidden": self.hidden, "blockers": self.blockers, "threshold": self.threshold,
                   "obs_shape": self.info["obs_shape"]}
        write_atomically(path, lambda tmp: th.save(payload, tmp))

    @property
    def hidden(self) -> int:
        return self.model.hidden

    @classmethod
    def load(cls, path: str | pathlib.Path) -> GeometryRisk:
        path = pathlib.Path(path)
        if not path.is_file():
            raise ValueError(f"geometry risk model {str(path)!r} does not exist "
                             "(python -m research.fall_geometry export, in the repository, makes one)")
        try:
            payload = th.load(path, map_location="cpu", weights_only=True)
            n = int(payload["features"])
            model = FeatureModel(np.zeros(n), np.ones(n), int(payload["hidden"]))
            model.load_state_dict(payload["state_dict"])
            model.eval()
            return cls(model, bool(payload["blockers"]), float(payload["threshold"]), tuple(payload["obs_shape"]))
        except ValueError:
            raise
        except Exception as err:  # noqa: BLE001  (any failure to read is a bad file)
            raise ValueError(f"{path} is not a readable geometry risk model: {err}") from err


class PickMask:
    """A test-time wrapper around ``policy`` (SB3's ``predict`` with ``action_masks``) that masks out some cells of
    its pick map before the policy chooses: `FallFilter` (the risky picks) and `shelf_env.pick_guard.PickGuard` (the
    wasted ones). It holds their layout checks and `choose`, which masks and stands aside where nothing allowed would
    be left. ``STATS`` names its two counters: decisions where it masked out at least one allowed pick cell, and
    decisions where nothing allowed was left, so that the policy chose as if unwrapped."""

    STATS = ("masked", "unmasked")

    def __init__(self, policy: Any, map_names: tuple[str, ...], rows: int, cols: int) -> None:
        name = type(self).__name__
        self.policy = policy
        self.observation_space, self.action_space = policy.observation_space, policy.action_space
        if "pick" not in map_names:
            raise ValueError(f"{name} needs a pick map; the policy's maps are {map_names}")
        self.pick, self.n_maps, self.rows, self.cols = map_names.index("pick"), len(map_names), rows, cols
        if int(self.action_space.n) != self.n_maps * rows * cols:
            raise ValueError(f"action space {self.action_space} is not {self.n_maps} maps of {rows}x{cols}")
        self.acts_masked = bool(getattr(policy, "acts_masked", True))
        self.stats = dict.fromkeys(self.STATS, 0)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """``observation`` as an array, checked to be one observation of the policy's shape."""
        obs = np.asarray(observation)
        if obs.shape != self.observation_space.shape:
            raise ValueError(f"{type(self).__name__} acts on one observation of shape {self.observation_space.shape}, "
                             f"got {obs.shape}")
        return obs

    def allowed(self, action_masks: np.ndarray | None) -> np.ndarray:
        """The caller's masks, flat (everything where it passed none)."""
        return (np.ones(int(self.action_space.n), bool) if action_masks is None
                else np.asarray(action_masks, bool).reshape(-1))

    def choose(self, obs: np.ndarray, allowed: np.ndarray, cells: np.ndarray, state: Any,
               deterministic: bool) -> tuple[np.ndarray, Any]:
        """The policy's action with the pick cells ``cells`` (bool ``(H, W)``) masked out of ``allowed``, or within
        ``allowed`` alone where that would leave nothing; counted in ``stats``."""
        banned = np.zeros((self.n_maps, self.rows, self.cols), bool)
        banned[self.pick] = cells
        return self.choose_actions(obs, allowed, banned.reshape(-1), state, deterministic)

    def choose_actions(self, obs: np.ndarray, allowed: np.ndarray, banned: np.ndarray, state: Any,
                       deterministic: bool) -> tuple[np.ndarray, Any]:
        """`choose` for any actions: the policy's action with the flat actions ``banned`` masked out of ``allowed``,
        or within ``allowed`` alone where that would leave nothing; counted in ``stats``."""
        masked, unmasked = self.STATS
        self.stats[masked] += int((allowed & banned).any())
        kept = allowed & ~banned
        if not kept.any():
            self.stats[unmasked] += 1
            kept = allowed
        return self.policy.predict(obs, state=state, deterministic=deterministic, action_masks=kept)


class FallFilter(PickMask):
    """Wrap ``policy`` (SB3's ``predict`` with ``action_masks``): pick cells whose predicted fall risk
    is at or over ``risk.threshold`` are masked out before the policy chooses (see the module
    docstring). Where that leaves no allowed action, the policy chooses as if unfiltered. Counts in
    ``stats``: ``masked`` (decisions where at least one allowed pick cell was masked out) and
    ``unfiltered`` (decisions where nothing allowed was left, so the filter stood aside)."""

    STATS = ("masked", "unfiltered")

    def __init__(self, policy: Any, risk: PickRisk, map_names: tuple[str, ...], rows: int, cols: int) -> None:
        super().__init__(policy, map_names, rows, cols)
        self.risk = risk
        trained_on = getattr(risk, "info", {}).get("obs_shape")
        if trained_on is not None and tuple(trained_on) != tuple(self.observation_space.shape):
            raise ValueError(f"the fall-risk model was trained on observations of shape {tuple(trained_on)}; the "
                             f"policy's are {tuple(self.observation_space.shape)} (another cell size or layout)")

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        obs, allowed = self.observation(observation), self.allowed(action_masks)
        risky = self.risk.risk(obs) >= self.risk.threshold
        if action_masks is None and not (allowed.reshape(self.n_maps, self.rows, self.cols)[self.pick] & ~risky).any():
            # a policy that gets no env masks (a heuristic) picks among object cells by itself: with
            # every cell risky there is nothing to restrict it to
            self.stats["unfiltered"] += 1
            return self.policy.predict(obs, state=state, deterministic=deterministic)
        return self.choose(obs, allowed, risky, state, deterministic)


#: Appended to a checkpoint's path: play it under `FallFilter` with `geometry_risk_path`'s model.
GEOMETRY_FILTER = "+geometry-filter"


def geometry_risk_path(checkpoint: str | os.PathLike) -> pathlib.Path:
    """The `GeometryRisk` a ``<checkpoint>+geometry-filter`` policy uses: ``<stem>.geometry_risk.pt`` beside it."""
    path = pathlib.Path(checkpoint)
    return path.with_name(path.stem + ".geometry_risk.pt")
