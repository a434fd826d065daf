"""Masked exploration: how an exploratory action is drawn from an action mask (the learner's and an
actor process's ε-greedy steps share it)."""

from __future__ import annotations

from typing import Any

import numpy as np


def draw_masked_action(mask: np.ndarray, n_maps: int, rng: Any) -> int:
    """One exploratory action from a boolean action mask: a map drawn uniformly among the maps with
    a useful pixel, then one of its useful pixels, so a primitive with a large mask (pushes) does
    not crowd out one with a small mask (picks). Uniform over all actions if the mask is empty.
    ``rng`` is anything with ``choice`` (``np.random`` or a ``np.random.Generator``)."""
    per_map = np.asarray(mask, dtype=bool).reshape(n_maps, -1)
    maps = np.flatnonzero(per_map.any(axis=1))
    if maps.size == 0:
        return int(rng.choice(per_map.size))
    m = int(rng.choice(maps))
    return m * per_map.shape[1] + int(rng.choice(np.flatnonzero(per_map[m])))
