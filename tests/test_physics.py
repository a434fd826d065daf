"""The cheaper action (`shelf_env.world.cabinet.Physics`): "fast" physics skips only what cannot matter.

Free motion (`Robot.move_linear` with ``skip_free_motion``) puts the arm on its path where nothing
is near instead of driving it there; these tests check that it skips the free parts, simulates
every contact, leaves the world untouched by its checks, and moves objects as the fully simulated
reference does. `benchmarks/physics_outcomes.py` compares outcomes over scene sets.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pybullet as pb
import pytest

from shelf_env.world.cabinet import PHYSICS, Physics
from tests.conftest import REGIONS, box


def make(physics: str):
    return gym.make("ShelfSort-v0", num_objects=2, physics=physics).unwrapped


def play(physics: str, scene, actions):
    """Object positions after each of ``actions`` ((map, x, y)) on ``scene``, and the robot's counts."""
    env = make(physics)
    try:
        env.reset(seed=0)
        env.set_scene(scene, REGIONS)
        out = []
        for name, x, y in actions:
            env.step(env.codec.action_at(name, x, y))
            out.append(env.world.positions().copy())
        return out, env.robot.physics_steps, env.robot.skipped_steps
    finally:
        env.close()


SCENE = [(box(h=0.08), 0, 0.20, 0.0, 0.0), (box(0.05, 0.05, 0.06, 0.2), 1, 0.30, -0.20, 0.0)]
ACTIONS = [("push_left", 0.20, -0.06), ("pick", 0.30, -0.20)]


def test_presets_and_parse():
    assert PHYSICS["reference"] == Physics(50, 1e-7, False)  # PyBullet's default solver, all simulated
    assert Physics.named("fast").skip_free_motion
    assert Physics.parse("20:1e-5:1") == Physics(20, 1e-5, True)
    assert Physics.parse("reference") is PHYSICS["reference"]


@pytest.mark.parametrize("bad", ["slow", "20:1e-5", "20:1e-5:yes", "x:1e-5:1", "0:1e-5:1", "20:-1:0"])
def test_bad_physics_is_a_clear_error(bad):
    with pytest.raises(ValueError, match="physics|solver"):
        Physics.parse(bad)
    with pytest.raises(ValueError, match="physics|solver"):
        gym.make("ShelfSort-v0", physics=bad)


def test_reference_simulates_everything_and_fast_skips_the_free_parts():
    ref_positions, ref_steps, ref_skipped = play("reference", SCENE, ACTIONS)
    fast_positions, fast_steps, fast_skipped = play("fast", SCENE, ACTIONS)
    assert ref_skipped == 0
    # the approaches, the carry and the exits are free here: most of the motion is not simulated
    assert fast_skipped > fast_steps
    assert fast_steps < 0.5 * ref_steps
    # ... and the objects end where the fully simulated robot leaves them (Bullet's noise aside)
    for ref, fast in zip(ref_positions, fast_positions):
        assert np.abs(ref - fast).max() < 5e-4


def test_a_push_is_simulated_where_the_blade_meets_the_object():
    env = make("fast")
    try:
        env.reset(seed=0)
        env.set_scene(SCENE, REGIONS)
        before = env.world.positions().copy()
        env.step(env.codec.action_at("push_left", 0.20, -0.06))
        moved = env.world.positions() - before
        assert moved[0, 1] > 0.03  # pushed towards +y: the blade meets it 2.5 cm into the 8 cm push
        assert np.abs(moved[1]).max() < 1e-4  # the far object is untouched
    finally:
        env.close()


def test_the_free_check_leaves_the_simulation_as_it_was():
    env = make("fast")
    try:
        env.reset(seed=0)
        env.set_scene(SCENE, REGIONS)
        robot, c = env.robot, env.client
        # hold the small box (6 cm) with its bottom 7 cm up, then look down a path through the cabinet
        held = env.world.objects[1].uid
        robot.teleport(np.array([0.30, -0.20, 0.06]))
        robot.grip(held)
        robot.teleport(np.array([0.30, -0.20, 0.13]))

        def state():
            joints = pb.getJointStates(robot.uid, robot.joints, physicsClientId=c)
            return ([j[:2] for j in joints], pb.getBasePositionAndOrientation(held, physicsClientId=c),
                    pb.getBaseVelocity(held, physicsClientId=c))

        before = state()
        q = robot.ik(np.array([[0.05, 0.0, 0.13], [0.20, 0.0, 0.13], [0.30, -0.20, 0.13]]))
        near = robot._near(q)
        assert state() == before  # bit for bit
        assert near.tolist() == [False, True, False]  # the held box meets the 8 cm one at (0.20, 0)
    finally:
        env.close()
