"""The place heuristic (`shelf_env.robot.placement.place_position`): the back of the region first, and with
``min_front`` (the closed loop's place check) never a footprint nearer the opening than that."""

from __future__ import annotations

import numpy as np
import pytest

from shelf_env import params
from shelf_env.camera.heightmap import FREE
from shelf_env.robot.placement import place_position

ROWS, COLS = 80, 120  # 0.40 m x 0.60 m at 5 mm
FOOTPRINT = (0.06, 0.06)


def region_left_third() -> np.ndarray:
    mask = np.zeros((ROWS, COLS), bool)
    mask[:, :40] = True
    return mask


def test_an_empty_region_gets_the_object_at_its_back_centre_line():
    cell_uid = np.full((ROWS, COLS), FREE)
    x, y = place_position(cell_uid, {}, region_left_third(), 0, FOOTPRINT, params.PIXEL_SIZE)
    # the footprint (6 cm + 1 cm margin, 15 cells) against the back wall, centred on the region's columns
    assert x == pytest.approx(0.40 - 7.5 * params.PIXEL_SIZE, abs=params.PIXEL_SIZE)
    assert y == pytest.approx(0.30 - 20 * params.PIXEL_SIZE, abs=params.PIXEL_SIZE)
    # min_front changes nothing where the back is free
    assert place_position(cell_uid, {}, region_left_third(), 0, FOOTPRINT, params.PIXEL_SIZE,
                          min_front=0.10) == (x, y)


def test_min_front_keeps_the_footprint_away_from_the_opening_in_a_full_region():
    # the region is full (an object of its own class) but for its front 9 cm: the free footprint
    # there is the heuristic's choice; with min_front = 0.10 the least covered one further in is
    cell_uid = np.full((ROWS, COLS), FREE)
    cell_uid[:62, :40] = 7
    region = region_left_third()
    x, _ = place_position(cell_uid, {7: 0}, region, 0, FOOTPRINT, params.PIXEL_SIZE)
    assert x - FOOTPRINT[0] / 2 < 0.10 and x + FOOTPRINT[0] / 2 <= 0.40 - 62 * params.PIXEL_SIZE + 1e-9
    x, _ = place_position(cell_uid, {7: 0}, region, 0, FOOTPRINT, params.PIXEL_SIZE, min_front=0.10)
    assert x - FOOTPRINT[0] / 2 >= 0.10
    # a min_front no centre of the region allows leaves the choice to the region alone
    x_far, _ = place_position(cell_uid, {7: 0}, region, 0, FOOTPRINT, params.PIXEL_SIZE, min_front=0.45)
    assert 0 < x_far < 0.40
