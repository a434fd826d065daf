"""Carries blocked by an object taller than any training object: ``<policy>+tall-guard``
(docs/experiments/ycb-kinds.md).

On the unseen (YCB) objects half the shipped policy's invalid greedy picks drop a neighbour, most often one of the two
17.5 cm kinds, and 19 of 29 such picks had a carry the camera itself sees as blocked (`carry_clear`), where the
learned fall filter ranks them poorly: its blocker features were fit on training objects, which stop at 12 cm
(`shelf_env.world.objects.TRAIN_HEIGHT`). `TallGuard` masks the pick cells whose straight carry out of the opening
is blocked (as `shelf_env.conditions.safe_picks.carry_clear` judges it, on the observation's colour blobs and
heights) by a visible object taller than ``tallest`` (default the training objects' tallest), where the fall model is
outside its data; other blocked carries are left to the fall filter. Where that would leave no allowed action the
policy chooses as if unguarded (`PickMask.choose`). It reads the observation only and is not learned.

    python -m research.evaluate --policies "p_s.zip+tall-guard+geometry-filter+pick-guard+loop-breaker" ...
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from shelf_env import params
from shelf_env.baselines.heuristics import ObservationView
from shelf_env.camera.heightmap import observed_height
from shelf_env.conditions.safe_picks import SIDE_M, TOLERANCE_M, Z_CARRY, _object, _tallest_on_path
from shelf_env.fall_filter import PickMask
from shelf_env.policies import register_wrapper
from shelf_env.world.objects import TRAIN_HEIGHT

#: The suffix: ``<checkpoint>+tall-guard+geometry-filter+pick-guard+loop-breaker``.
TALL_GUARD = "+tall-guard"


def tall_blocked_cells(obs: np.ndarray, tallest: float = TRAIN_HEIGHT[1],
                       view: ObservationView | None = None) -> np.ndarray:
    """Bool ``(H, W)``: the object cells of ``obs`` whose straight carry out of the opening is blocked
    (`carry_clear`'s rule: the cell's height plus the tallest visible object in the corridor reaches the carry
    height less its tolerance) where that tallest object is taller than ``tallest`` metres. ``view``: ``obs`` already
    read (`ObservationView.from_observation` with ``margin_cells=0``), so that a caller who holds it does not read it
    twice."""
    obs = np.asarray(obs)
    if obs.ndim != 3 or obs.shape[0] != 4:
        raise ValueError(f"tall_blocked_cells reads one (4, H, W) observation, got shape {obs.shape}")
    view = ObservationView.from_observation(obs, margin_cells=0) if view is None else view
    blob, height = view.blob, observed_height(obs)
    side_cells = int(round(SIDE_M / (params.CABINET_DEPTH / obs.shape[1])))
    out = np.zeros(blob.shape, bool)
    for b in range(int(blob.max()) + 1):
        own, box, obstacle = _object(blob, height, b)
        top = _tallest_on_path(obstacle, box, 0, side_cells)
        if top is not None and top > tallest:
            out |= own & (height + top >= Z_CARRY - TOLERANCE_M)
    return out


class TallGuard(PickMask):
    """Wrap ``policy`` (SB3's ``predict`` with ``action_masks``): the pick cells of `tall_blocked_cells` are masked
    out before it chooses (module docstring)."""

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        obs = self.observation(observation)
        return self.choose(obs, self.allowed(action_masks), tall_blocked_cells(obs), state, deterministic)


def _wrap(agent: Any, env: gym.Env, base: str) -> TallGuard:
    unwrapped: Any = env.unwrapped
    return TallGuard(agent, tuple(unwrapped.map_names), unwrapped.rows, unwrapped.cols)


register_wrapper(TALL_GUARD, _wrap)
