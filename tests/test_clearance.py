"""Safe picks (`shelf_env.conditions.safe_picks`, ``ShelfSortEnv(safe_picks=True)``): a pick whose object would be
carried out of the opening through a taller neighbour is left out of the mask and of the
heuristics' choices, and the carry that the mask allows leaves the neighbour in the cabinet."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from shelf_env.baselines.heuristics import AccessibilityHeuristic, DistanceHeuristic
from shelf_env.conditions.safe_picks import Z_CARRY, carry_clear, carry_path
from shelf_env.evaluation.protocol import check_conditions
from shelf_env.world.cabinet import Region
from tests.conftest import REGIONS
from tests.test_closed_loop import CLEAN_SCENE, DRAG_SCENE


def heightmap(*objects: tuple[int, int, int, int, float]) -> tuple[np.ndarray, np.ndarray]:
    """(labels, height) of 80 x 120 cells with objects (row0, row1, col0, col1, height), label = index."""
    labels, height = np.full((80, 120), -1), np.zeros((80, 120))
    for k, (r0, r1, c0, c1, h) in enumerate(objects):
        labels[r0:r1, c0:c1], height[r0:r1, c0:c1] = k, h
    return labels, height


def test_z_carry_is_the_picks_carry_height():
    assert Z_CARRY == pytest.approx(0.27 - 0.08 - 0.005)


def test_a_tall_object_behind_a_tall_one_is_not_clear_and_the_front_one_is():
    labels, height = heightmap((10, 20, 50, 60, 0.12), (60, 70, 52, 62, 0.08))  # back 12 cm, front 8 cm
    clear = carry_clear(labels, height)
    assert not clear[labels == 0].any()  # 0.12 + 0.08 > 0.185: it would sweep the front one
    assert clear[labels == 1].all()  # nothing in front of the front one
    assert not clear[labels < 0].any()  # only object cells are ever clear


def test_the_corridor_is_the_objects_columns_from_its_back_to_the_front():
    # the front object beside the corridor (one 5 mm cell of margin left between them): clear
    labels, height = heightmap((10, 20, 50, 60, 0.12), (60, 70, 61, 71, 0.08))
    assert carry_clear(labels, height)[labels == 0].all()
    # touching the corridor's margin: not clear
    labels, height = heightmap((10, 20, 50, 60, 0.12), (60, 70, 60, 70, 0.08))
    assert not carry_clear(labels, height)[labels == 0].any()
    # behind it does not matter: only what lies between the object and the opening
    labels, height = heightmap((40, 50, 50, 60, 0.12), (10, 20, 50, 60, 0.15))
    assert carry_clear(labels, height)[labels == 0].all()


def test_the_held_objects_hang_is_its_pick_cells_height():
    # a short neighbour in front: a 10 cm object clears it (0.10 + 0.06 < 0.18), a 13 cm one does not
    for h, ok in ((0.10, True), (0.13, False)):
        labels, height = heightmap((10, 20, 50, 60, h), (60, 70, 50, 60, 0.06))
        assert carry_clear(labels, height)[labels == 0].all() == ok


def test_carry_clear_rejects_maps_of_different_shapes():
    with pytest.raises(ValueError, match="one shape"):
        carry_clear(np.zeros((80, 120), int), np.zeros((80, 119)))


def test_carry_path_is_straight_exactly_where_carry_clear_says_so():
    rng = np.random.default_rng(0)
    for _ in range(30):
        objects = []
        for _ in range(8):
            r, c, h, w = rng.integers(0, 72), rng.integers(0, 110), rng.integers(4, 10), rng.integers(4, 10)
            objects.append((r, r + h, c, c + w, rng.uniform(0.03, 0.17)))
        labels, height = heightmap(*objects)
        clear = carry_clear(labels, height)
        rows, cols = np.nonzero(labels >= 0)
        for k in rng.choice(len(rows), 10):
            r, c = rows[k], cols[k]
            assert (carry_path(labels, height, r, c, max_shift=0.0) == 0) == clear[r, c]
            path = carry_path(labels, height, r, c)
            assert (path == 0) == clear[r, c]  # straight out whenever that is clear, and only then


def test_carry_path_takes_the_nearest_clear_shift_with_a_clear_sideways_carry():
    # a 12 cm object behind an 8 cm one: straight out it sweeps the front one (as carry_clear says)
    back, front = (10, 20, 50, 60, 0.12), (60, 70, 50, 60, 0.08)
    labels, height = heightmap(back, front)
    # 11 cells (5.5 cm) either way clears the front one and its 1-cell margin; the -y.. side first on a tie
    assert carry_path(labels, height, 15, 55) == -11
    # an 8 cm object beside it on that side: the sideways carry would sweep it, so the other side
    labels, height = heightmap(back, front, (10, 20, 30, 40, 0.08))
    assert carry_path(labels, height, 15, 55) == 11
    # and one more in front on that side (columns 66..75): the first way out past it
    labels, height = heightmap(back, front, (10, 20, 30, 40, 0.08), (60, 70, 66, 76, 0.08))
    assert carry_path(labels, height, 15, 55) == 27  # columns 76..85 with the margin: 49 + 27 = 76
    # not within reach: None
    assert carry_path(labels, height, 15, 55, max_shift=0.1) is None
    # a short neighbour beside it is no obstacle to the sideways carry (0.04 < 0.185 - 0.12 - 0.005)
    labels, height = heightmap(back, front, (10, 20, 30, 40, 0.04))
    assert carry_path(labels, height, 15, 55) == -11


def test_carry_path_keeps_a_shifted_object_off_the_walls_and_knows_nothing_of_empty_cells():
    # against the wall at column 0 with a tall one in front: only shifts towards the middle
    labels, height = heightmap((10, 20, 0, 10, 0.12), (60, 70, 0, 10, 0.08))
    assert carry_path(labels, height, 15, 5) == 11
    labels, height = heightmap((10, 20, 0, 10, 0.12))
    assert carry_path(labels, height, 15, 5) == 0  # straight out is judged wherever the object is
    assert carry_path(labels, height, 40, 60) == 0  # an empty cell: nothing known, straight
    with pytest.raises(ValueError, match=r"cell \(80, 0\) is outside the 80x120 map"):
        carry_path(labels, height, 80, 0)
    with pytest.raises(ValueError, match="one shape"):
        carry_path(labels, height[:, 1:], 15, 5)


def scene_env(scene, regions=REGIONS, **kwargs):
    env = gym.make("ShelfSort-v0", num_objects=2, **kwargs).unwrapped
    env.reset(seed=0)
    env.set_scene(scene, regions)
    return env


def test_with_the_lane_check_safe_picks_counts_a_clear_detour_as_clear():
    # DRAG_SCENE's back box has no clear straight carry but one 5.5 cm to the side
    for closed_loop, reach, allowed in ((False, 0.0, False), ({"lane": False}, 0.0, False), (True, 0.2, True),
                                        ({"detour_max": 0.05}, 0.05, False)):
        env = scene_env(DRAG_SCENE, safe_picks=True, closed_loop=closed_loop)
        try:
            assert env.detour_reach == reach
            assert env.action_masks()[env.codec.action_at("pick", 0.30, 0.0)] == allowed
            assert DistanceHeuristic(env).detour_reach == reach
        finally:
            env.close()


def test_safe_picks_mask_leaves_out_the_pick_that_drags_the_neighbour_out():
    env = scene_env(DRAG_SCENE, safe_picks=True)
    try:
        mask = env.action_masks()
        back, front = env.codec.action_at("pick", 0.30, 0.0), env.codec.action_at("pick", 0.06, 0.0)
        assert not mask[back] and mask[front]
        # the pushes are untouched by safe_picks
        plain = scene_env(DRAG_SCENE)
        try:
            n = env.rows * env.cols
            assert np.array_equal(mask[n:], plain.action_masks()[n:])
            assert plain.action_masks()[back]
        finally:
            plain.close()
        # what the mask allows is the carry that leaves both objects in the cabinet (and here sorts them)
        _, reward, _, _, info = env.step(front)
        assert not info["fell"] and reward != -10 and len(env.world.objects) == 2
    finally:
        env.close()


def test_safe_picks_changes_nothing_where_every_carry_is_clear():
    env, plain = scene_env(CLEAN_SCENE, safe_picks=True), scene_env(CLEAN_SCENE)
    try:
        assert np.array_equal(env.action_masks(), plain.action_masks())
    finally:
        env.close()
        plain.close()


def test_h_d_with_safe_picks_picks_the_front_object_first():
    # the drag scene's boxes, both misplaced: the back one (class 0, region on the right) is farther
    # from its region than the front one (class 1, region on the left), so H-d goes for it first,
    # and would drag the front one out, unless safe_picks rules its carry out
    regions = [Region(0.0, 0.40, -0.30, -0.12), Region(0.0, 0.40, 0.12, 0.30), Region(0.0, 0.40, -0.09, 0.09)]
    scene = [(DRAG_SCENE[0][0], 0, 0.30, 0.05, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.05, 0.0)]
    for safe, expected_x in ((False, 0.30), (True, 0.06)):
        env = scene_env(scene, regions, safe_picks=safe)
        try:
            _, row, col = env.decode_action(int(DistanceHeuristic(env).predict(env._observe())[0]))
            x, _ = env.codec.cell_centre(row, col)
            assert abs(x - expected_x) < 0.04, (safe, x)
        finally:
            env.close()


def test_heuristics_keep_their_choice_when_no_misplaced_object_has_a_clear_carry():
    # only the back box is misplaced (class 0, region on the left; the front one, class 1, stands in
    # its region in the middle): there is no clear alternative, so the choice is the plain one
    scene = [(DRAG_SCENE[0][0], 0, 0.30, 0.0, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.0, 0.0)]
    for heuristic in (DistanceHeuristic, AccessibilityHeuristic):
        choices = []
        for safe in (False, True):
            env = scene_env(scene, safe_picks=safe)
            try:
                choices.append(int(heuristic(env).predict(env._observe())[0]))
            finally:
                env.close()
        assert choices[0] == choices[1]
        _, row, _ = env.decode_action(choices[1])
        assert abs(env.codec.cell_centre(row, 0)[0] - 0.30) < 0.04  # the back box


def test_safe_picks_must_be_a_bool():
    with pytest.raises(ValueError, match="safe_picks"):
        gym.make("ShelfSort-v0", safe_picks="yes")
    with pytest.raises(ValueError, match="safe_picks"):
        check_conditions({"safe_picks": 1})
    assert check_conditions({"safe_picks": True}) == {"safe_picks": True}
