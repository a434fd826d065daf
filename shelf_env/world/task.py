"""The task's rules (§III, Eq. 2), apart from the physics and the camera: valid, sorted, reward.

`judge` reads the world after a primitive has settled and says what the step achieved:

- *fell*: some object is outside the cabinet (`shelf_env.world.cabinet.World.inside`);
- *valid*: nothing fell and every object inside is at rest;
- *sorted*: valid and every object is in the region of its own class;
- reward ``REWARD_INVALID`` (-10) if not valid, ``REWARD_SORTED`` (0) if sorted, else
  ``REWARD_STEP`` (-1); the episode terminates on sorted or invalid;
- *relabel*: valid, not sorted, yet every object lies in some region. Hindsight relabelling
  (§IV-D.3) then recolours each object with the class of the region it is in, and that relabelled
  scene is sorted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shelf_env import params
from shelf_env.world.cabinet import World


@dataclass(frozen=True)
class Judgement:
    """What the world looks like to the task's rules after a step (arrays per object)."""

    inside: np.ndarray  # bool, every object in the world
    resting: np.ndarray  # bool, the objects inside
    region: np.ndarray  # region index (-1: none), the objects inside
    classes: np.ndarray  # class, the objects inside
    fell: bool
    valid: bool
    sorted: bool

    @property
    def reward(self) -> float:
        return self.reward_with()

    def reward_with(self, invalid: float = params.REWARD_INVALID) -> float:
        """Eq. 2 with ``invalid`` as the reward of an invalid step (the env's ``invalid_reward``)."""
        if not self.valid:
            return float(invalid)
        return float(params.REWARD_SORTED if self.sorted else params.REWARD_STEP)

    @property
    def num_sorted(self) -> int:
        """How many of the objects inside lie in their own class's region (``info["num_sorted"]``)."""
        return int((self.region == self.classes).sum())

    @property
    def terminated(self) -> bool:
        return self.sorted or not self.valid

    @property
    def relabel(self) -> bool:
        """Whether hindsight relabelling applies: valid, not sorted, every object in some region."""
        return self.valid and not self.sorted and bool((self.region >= 0).all())

    def is_success(self, num_objects: int) -> bool:
        """Sorted with all ``num_objects`` of the episode still there."""
        in_own = self.region == self.classes
        return (not self.fell and len(in_own) == num_objects and bool(in_own.all())
                and bool(self.resting.all()))


def judge(world: World) -> Judgement:
    """The rules applied to ``world`` as it is now (before fallen objects are removed)."""
    pos = world.positions()
    inside = world.inside(pos)
    resting = world.at_rest()[inside]
    region = world.region_of(pos[inside])
    classes = world.classes()[inside]
    fell = bool((~inside).any())
    valid = not fell and bool(resting.all())
    sorted_ = valid and bool((region == classes).all())
    return Judgement(inside, resting, region, classes, fell, valid, sorted_)
