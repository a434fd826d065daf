"""Perception noise: what a real segmentation and depth pipeline gets wrong (§VI), off by default.

``ShelfSortEnv(perception_noise=...)`` passes every capture's semantic map (cell -> object uid,
FREE or OCCLUDED, and height) through a `PerceptionNoise` before anything reads it. The policy's
observation, the action masks, the place heuristic, the pick's approach height and hindsight
relabelling all see the noisy map, as they would on a robot; rewards and success are decided on
the true world state. Per capture, independently:

- ``dropout``: each visible object is missing from the masks with this probability: its cells
  read as free floor (white, or its region's tint). The camera still measured their depth, so the
  height channel keeps the object's height.
- ``part_dropout``: each visible object loses part of its mask with this probability: the cells
  on one side of a random line through the centre of its visible cells read as free floor.
- ``class_flip``: each visible object is shown in another class's colour (uniform among the
  other two) with this probability.
- ``depth_sigma``: Gaussian noise of this standard deviation (metres) on every cell's height,
  clipped at the floor.

The noise draws from its own generator, seeded from the env's ``np_random`` when an episode
starts, so an episode stays bit-identical given (scene seed, actions). All-zero noise is no noise:
the env then draws nothing and behaves bit for bit as without the option.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from shelf_env import params
from shelf_env.camera.heightmap import FREE

PROBABILITIES = ("dropout", "part_dropout", "class_flip")


@dataclass(frozen=True)
class PerceptionNoise:
    """Segmentation dropout (whole objects or parts), class flips and depth noise (see the module)."""

    dropout: float = 0.0
    part_dropout: float = 0.0
    class_flip: float = 0.0
    depth_sigma: float = 0.0

    def __post_init__(self) -> None:
        for name in PROBABILITIES:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
                raise ValueError(f"perception_noise {name} must be a probability in [0, 1], got {value!r}")
        sigma = self.depth_sigma
        if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or not (math.isfinite(sigma) and sigma >= 0):
            raise ValueError(f"perception_noise depth_sigma must be a finite number of metres >= 0, got {sigma!r}")

    @classmethod
    def from_any(cls, value: PerceptionNoise | dict[str, Any] | None) -> PerceptionNoise | None:
        """A `PerceptionNoise` from the env's ``perception_noise`` argument (None: no noise)."""
        if value is None or isinstance(value, PerceptionNoise):
            return value
        if not isinstance(value, dict):
            raise ValueError(f"perception_noise must be a dict, a PerceptionNoise or None, got {value!r}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ValueError(f"unknown perception_noise keys {unknown}; known: {known}")
        return cls(**value)

    @property
    def active(self) -> bool:
        return any(getattr(self, f.name) > 0 for f in dataclasses.fields(self))

    def apply(self, cell_uid: np.ndarray, height: np.ndarray, class_of_uid: dict[int, int],
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
        """The noisy (cell_uid, height) and the class each visible object is shown with."""
        cell_uid, height = cell_uid.copy(), height.copy()
        shown = dict(class_of_uid)
        visible = [uid for uid in class_of_uid if (cell_uid == uid).any()]
        for uid in visible:
            cells = cell_uid == uid
            if self.dropout and rng.random() < self.dropout:
                cell_uid[cells] = FREE
                continue
            if self.part_dropout and rng.random() < self.part_dropout:
                rows, cols = np.nonzero(cells)
                angle = rng.uniform(0.0, 2 * np.pi)
                side = (rows - rows.mean()) * np.cos(angle) + (cols - cols.mean()) * np.sin(angle) > 0
                cell_uid[rows[side], cols[side]] = FREE
            if self.class_flip and rng.random() < self.class_flip:
                others = [k for k in range(params.NUM_CLASSES) if k != class_of_uid[uid]]
                shown[uid] = int(others[int(rng.integers(len(others)))])
        if self.depth_sigma:
            height = np.clip(height + rng.normal(0.0, self.depth_sigma, size=height.shape), 0.0, None)
        return cell_uid, height, shown
