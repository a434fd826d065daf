"""Closed-loop primitives (`ShelfSortEnv(closed_loop=True)`, `shelf_env.robot.DragWatch`): the retract
after a pick that drags a neighbour out of the cabinet open loop is caught by the cup's force
sensor and the object is put down; a clean pick is left alone."""

from __future__ import annotations

import gymnasium as gym
import pytest

from shelf_env.objects import ObjectSpec
from tests.conftest import REGIONS


def tall(h: float, mass: float) -> ObjectSpec:
    return ObjectSpec("cuboid", "box", (0.05, 0.05, h), mass)


# a 14 cm box at the back, a light 10 cm box in front of it near the opening: the picked box hangs
# low enough under the cup to drag the front one out as it is carried out
DRAG_SCENE = [(tall(0.14, 0.3), 1, 0.30, 0.0, 0.0), (tall(0.10, 0.15), 2, 0.06, 0.0, 0.0)]
CLEAN_SCENE = [(tall(0.14, 0.3), 1, 0.30, 0.0, 0.0), (tall(0.10, 0.15), 2, 0.06, 0.20, 0.0)]


def pick_back_box(scene, closed_loop: bool, physics: str = "fast"):
    env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=closed_loop, physics=physics).unwrapped
    try:
        env.reset(seed=0)
        env.set_scene(scene, REGIONS)
        _, reward, terminated, _, info = env.step(env.codec.action_at("pick", 0.30, 0.0))
        return reward, terminated, info, env.world.positions()
    finally:
        env.close()


def test_open_loop_retract_drags_the_neighbour_out():
    reward, terminated, info, _ = pick_back_box(DRAG_SCENE, closed_loop=False)
    assert info["fell"] and reward == -10 and terminated
    assert "interventions" not in info  # open loop reports nothing


def test_closed_loop_catches_the_drag_and_puts_the_object_down():
    reward, terminated, info, positions = pick_back_box(DRAG_SCENE, closed_loop=True)
    assert not info["fell"] and reward == -1 and not terminated
    (event,) = info["interventions"]
    assert event["primitive"] == "pick" and event["phase"] == "retreat" and event["reaction"] == "put down in place"
    assert event["force_n"] > 0.25
    assert len(positions) == 2 and (positions[:, 0] > 0).all()  # both objects still inside


def test_closed_loop_leaves_a_clean_pick_alone():
    # every motion simulated, so that the watched moves (always simulated) compare step for step
    open_loop = pick_back_box(CLEAN_SCENE, closed_loop=False, physics="reference")
    closed = pick_back_box(CLEAN_SCENE, closed_loop=True, physics="reference")
    assert closed[2]["interventions"] == []
    assert closed[0] == open_loop[0] and not closed[2]["fell"]
    assert closed[3] == pytest.approx(open_loop[3], abs=1e-6)  # the same motion, bit for bit up to float noise
