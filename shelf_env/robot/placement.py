"""The place heuristic of §IV-B.2 (Fig. 6).

Given what the robot sees (the semantic heightmap), the class of the held object and its
footprint, choose where to put it: inside its class's target region, on cells seen to be free
(occluded cells count as possibly occupied), as far back as possible, near the region's centre
line, and not in front of objects of other classes (which it would hide from the camera and
block from the tool). Used by the env and by the heuristic baselines alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shelf_env import params
from shelf_env.actions import cell_centres
from shelf_env.camera.heightmap import FREE


@dataclass(frozen=True)
class PlaceWeights:
    """Relative weights of the three preferences (per metre, per metre, per blocked cell)."""

    back: float = 1.0
    centre: float = 1.0
    obstruct: float = 0.02


def _window_sum(mask: np.ndarray, kh: int, kw: int) -> np.ndarray:
    """Sum of ``mask`` over the kh x kw window centred on every cell (zero padding)."""
    ph, pw = kh // 2, kw // 2
    padded = np.pad(mask.astype(np.int64), ((ph + 1, kh - ph), (pw + 1, kw - pw)))
    ii = padded.cumsum(0).cumsum(1)
    h, w = mask.shape
    return ii[kh:kh + h, kw:kw + w] - ii[:h, kw:kw + w] - ii[kh:kh + h, :w] + ii[:h, :w]


def place_position(
    cell_uid: np.ndarray,
    class_of_uid: dict[int, int],
    region_mask: np.ndarray,
    cls: int,
    footprint: tuple[float, float],
    pixel_size: float = params.PIXEL_SIZE,
    ignore_uid: int | None = None,
    margin: float = 0.01,
    weights: PlaceWeights = PlaceWeights(),
    min_front: float = 0.0,
) -> tuple[float, float]:
    """Cabinet (x, y) where to release an object of class ``cls``.

    ``cell_uid``: semantic map (rows back -> front, cols left -> right); ``region_mask``: cells of
    the class's target region; ``footprint``: the held object's (x, y) extent; ``ignore_uid``:
    the held object, whose old cells are free now; ``min_front``: metres behind the opening the
    footprint's front edge must stay (the closed loop's place check, `shelf_env.conditions.closed_loop.DragWatch`),
    unless no centre in the region allows it.
    """
    rows, cols = cell_uid.shape
    occupied = cell_uid != FREE
    if ignore_uid is not None:
        occupied &= cell_uid != ignore_uid
    kh = int(np.ceil((footprint[0] + margin) / pixel_size)) | 1
    kw = int(np.ceil((footprint[1] + margin) / pixel_size)) | 1
    blocked = _window_sum(occupied, kh, kw)
    outside_region = _window_sum(~region_mask, kh, kw)
    # other-class objects behind each cell, summed over the footprint's columns
    other = np.zeros_like(occupied)
    for uid, c in class_of_uid.items():
        if c != cls and uid != ignore_uid:
            other |= cell_uid == uid
    behind = np.vstack([np.zeros((1, cols), np.int64), np.cumsum(other, axis=0)[:-1]])
    behind_win = _window_sum(behind > 0, 1, kw)
    x, y = cell_centres(rows, cols, pixel_size)
    region_cols = np.flatnonzero(region_mask.any(0))
    yc = y[region_cols].mean() if len(region_cols) else 0.0
    score = (weights.back * x[:, None] - weights.centre * np.abs(y[None, :] - yc)
             - weights.obstruct * behind_win)
    # feasibility in order of preference: free and fully inside the region; free with the
    # centre in the region; otherwise the least blocked centre in the region
    centre_in = region_mask.copy()
    # keep the footprint inside the cabinet
    centre_in[: kh // 2] = False
    centre_in[rows - kh // 2:] = False
    centre_in[:, : kw // 2] = False
    centre_in[:, cols - kw // 2:] = False
    if min_front > 0:
        centre_in &= (x - footprint[0] / 2 >= min_front)[:, None]
    if not centre_in.any():
        centre_in = region_mask
    for feasible in (centre_in & (blocked == 0) & (outside_region == 0), centre_in & (blocked == 0)):
        if feasible.any():
            best = np.argmax(np.where(feasible, score, -np.inf))
            r, c = divmod(int(best), cols)
            return float(x[r]), float(y[c])
    least = np.where(centre_in, blocked.astype(float) - 1e-3 * score, np.inf)
    r, c = divmod(int(np.argmin(least)), cols)
    return float(x[r]), float(y[c])
