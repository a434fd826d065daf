"""research/tall_guard.py: ``+tall-guard`` masks the picks whose straight carry is blocked by a visible object taller
than any training object, leaves carries blocked by shorter objects and clear ones alone, and stands aside where
nothing allowed would be left."""

import numpy as np
import pytest
from pixel_envs import ScoresPolicy
from test_pick_guard import paint

from research.tall_guard import TallGuard, tall_blocked_cells
from shelf_env import policies
from shelf_env.camera.heightmap import CLASS_RGB
from shelf_env.conditions.safe_picks import Z_CARRY

H, W, MAPS = 40, 60, 3
NAMES = ("pick", "push_left", "push_right")


def crafted():
    """1 cm cells, row 0 at the back. A (6 cm) behind T (17.5 cm, taller than any training object): blocked by a tall
    object. B (8 cm) behind S (11 cm): blocked, by an object of the training heights. C (5 cm) with nothing in front;
    T and S themselves at the front."""
    obs = np.full((4, H, W), 255, np.uint8)
    obs[3] = 0
    paint(obs, slice(5, 10), slice(10, 15), CLASS_RGB[0], 0.06)  # A
    paint(obs, slice(30, 34), slice(10, 15), CLASS_RGB[1], 0.175)  # T
    paint(obs, slice(5, 10), slice(30, 35), CLASS_RGB[2], 0.08)  # B
    paint(obs, slice(30, 34), slice(30, 35), CLASS_RGB[1], 0.11)  # S
    paint(obs, slice(5, 10), slice(50, 55), CLASS_RGB[0], 0.05)  # C
    return obs


def flat(m, row, col):
    return m * H * W + row * W + col


def test_only_carries_blocked_by_an_object_taller_than_the_training_objects_are_masked():
    assert 0.06 + 0.175 > Z_CARRY and 0.08 + 0.11 > Z_CARRY  # both carries are blocked
    obs = crafted()
    blocked = tall_blocked_cells(obs)
    assert blocked[5:10, 10:15].all() and blocked.sum() == 25  # every cell of A, nothing else
    lower = tall_blocked_cells(obs, tallest=0.10)  # S (11 cm) counts as tall too
    assert lower[5:10, 30:35].all() and lower.sum() == 50
    with pytest.raises(ValueError, match=r"\(4, H, W\)"):
        tall_blocked_cells(obs[None])


def test_the_guard_masks_the_tall_blocked_picks_and_stands_aside_when_nothing_else_is_allowed():
    scores = np.zeros(MAPS * H * W)
    scores[flat(0, 7, 12)] = 3.0  # A: best, blocked by T
    scores[flat(0, 7, 32)] = 2.0  # B: blocked by S, which the training objects cover
    scores[flat(0, 7, 52)] = 1.0  # C
    guard = TallGuard(ScoresPolicy(scores, (4, H, W)), NAMES, H, W)
    obs = crafted()
    assert int(guard.predict(obs)[0]) == flat(0, 7, 32)
    assert guard.stats == {"masked": 1, "unmasked": 0}
    only_a = np.zeros(MAPS * H * W, bool)
    only_a[flat(0, 7, 12)] = True
    assert int(guard.predict(obs, action_masks=only_a)[0]) == flat(0, 7, 12)  # nothing else allowed: A after all
    assert guard.stats == {"masked": 2, "unmasked": 1}
    with pytest.raises(ValueError, match="shape"):
        guard.predict(np.zeros((1, 4, H, W)))
    assert policies.policy_wrappers("m.zip+tall-guard+geometry-filter+pick-guard+loop-breaker") == (
        "m.zip", ("+tall-guard", "+geometry-filter", "+pick-guard", "+loop-breaker"))
