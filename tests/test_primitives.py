"""The two primitives and the reward on crafted scenes (real physics)."""

import numpy as np

from shelf_env import params
from tests.conftest import REGIONS, action_at, box


def test_push_moves_object_about_push_length_in_commanded_direction(env):
    for name, sign in (("push_right", -1.0), ("push_left", +1.0)):
        # class 0's region is y >= 0.12: an 8 cm push from y = 0 cannot sort it
        env.set_scene([(box(), 0, 0.20, 0.0, 0.0)], REGIONS)
        p0 = env.world.positions()[0]
        # start just beside the object's face, on the side opposite the push direction; the
        # suction cup under the blade's tip (13 mm radius) is the tool's widest part there
        start_y = -sign * 0.05
        obs, reward, terminated, truncated, info = env.step(action_at(env, name, 0.20, start_y))
        d = env.world.positions()[0] - p0
        assert info["primitive"] == name and reward == params.REWARD_STEP and not terminated
        assert 0.06 <= sign * d[1] <= 0.09, d  # ~8 cm (less the gap between blade and face)
        assert abs(d[0]) < 0.015, d


def test_pick_and_place_moves_object_into_its_region(env):
    # a green (class 0) box in the blue region's half; green's region is on the left (+y)
    env.set_scene([(box(0.05, 0.05, 0.07), 0, 0.15, -0.20, 0.3)], REGIONS)
    assert not env.world.in_own_region()[0]
    obs, reward, terminated, truncated, info = env.step(action_at(env, "pick", 0.15, -0.20))
    pos = env.world.positions()[0]
    assert env.world.in_own_region()[0], pos
    assert reward == params.REWARD_SORTED and terminated and info["is_success"]
    assert pos[0] > 0.25  # the place heuristic puts it towards the back


def test_pick_on_empty_floor_grips_nothing(env):
    env.set_scene([(box(), 0, 0.30, -0.20, 0.0)], REGIONS)
    p0 = env.world.positions()[0]
    _, reward, terminated, _, info = env.step(action_at(env, "pick", 0.10, 0.20))
    assert reward == params.REWARD_STEP and not terminated
    assert np.allclose(env.world.positions()[0], p0, atol=0.003)
    assert env.robot.held is None


def test_object_knocked_out_of_the_front_gives_minus_ten_and_terminates(env):
    # Lateral pushes cannot move anything out of the open front, so the way out is the
    # paper's failure case (§V-d): retracting with a picked object drags a light object in
    # front of it over the front edge. The picked object is carried as high as the ceiling
    # allows, so it takes one almost as tall as the cabinet (like the YCB sugar box) to drag.
    tall = box(0.05, 0.05, 0.17, mass=0.3)
    light = box(0.04, 0.04, 0.06, mass=0.05)
    env.set_scene([(tall, 1, 0.25, 0.0, 0.0), (light, 2, 0.03, 0.0, 0.0)], REGIONS)
    n_before = len(env.world.objects)
    _, reward, terminated, truncated, info = env.step(action_at(env, "pick", 0.25, 0.0))
    assert info["fell"] and reward == params.REWARD_INVALID and terminated and not truncated
    assert not info["is_success"]
    assert len(env.world.objects) == n_before - 1  # the fallen object was removed


def test_truncation_after_max_actions():
    import gymnasium as gym
    env = gym.make("ShelfSort-v0", num_objects=1, max_actions=2).unwrapped
    env.set_scene([(box(), 0, 0.30, -0.20, 0.0)], REGIONS)
    _, _, term, trunc, _ = env.step(action_at(env, "push_left", 0.05, 0.25))
    assert not term and not trunc
    _, _, term, trunc, info = env.step(action_at(env, "push_left", 0.05, 0.25))
    assert not term and trunc and info["action_count"] == 2
    env.close()


def test_hindsight_relabelled_transition_when_all_in_wrong_regions(env):
    from shelf_env.camera.heightmap import CLASS_RGB
    # green object in yellow's region and yellow object in green's: every object is in some
    # region but none in its own; a push in empty space keeps it that way
    env.set_scene([(box(), 0, 0.30, 0.0, 0.0), (box(), 1, 0.30, 0.21, 0.0)], REGIONS)
    obs, reward, terminated, _, info = env.step(action_at(env, "push_right", 0.05, -0.25))
    assert reward == params.REWARD_STEP and not terminated
    rel = info["relabelled"]
    assert rel["reward"] == params.REWARD_SORTED and rel["terminated"] is True
    for key in ("obs", "next_obs"):
        assert rel[key].shape == obs.shape and rel[key].dtype == np.uint8
    cell_uid = env._semantic[0]
    green_uid, yellow_uid = (o.uid for o in env.world.objects)
    rgb = rel["next_obs"][:3].transpose(1, 2, 0)
    assert (rgb[cell_uid == green_uid] == CLASS_RGB[1]).all()  # now coloured as yellow's class
    assert (rgb[cell_uid == yellow_uid] == CLASS_RGB[0]).all()
    assert np.array_equal(rel["next_obs"][3], obs[3])  # heights are untouched
    # a step that leaves an object outside every region gives no relabelled transition
    env.set_scene([(box(), 0, 0.30, 0.0, 0.0), (box(), 1, 0.30, 0.21, 0.0)],
                  [REGIONS[0], REGIONS[1].__class__(0.35, 0.40, -0.09, 0.09), REGIONS[2]])
    _, _, _, _, info = env.step(action_at(env, "push_right", 0.05, -0.25))
    assert "relabelled" not in info


def test_set_scene_rejects_bad_input_before_touching_the_scene(env):
    import pytest
    before = [o.uid for o in env.world.objects]
    with pytest.raises(ValueError, match="class must be in"):
        env.set_scene([(box(), 0, 0.2, 0.0, 0.0), (box(), 3, 0.3, 0.2, 0.0)], REGIONS)
    with pytest.raises(ValueError, match="regions"):
        env.set_scene([(box(), 0, 0.2, 0.0, 0.0)], REGIONS[:2])
    assert [o.uid for o in env.world.objects] == before


def test_sleeping_objects_move_as_awake_ones():
    """Bullet's sleeping is a speed-up only: a push through a chain of two sleeping boxes and a
    pick of the second one end where they end with every object simulated at every step."""
    import gymnasium as gym

    finals = {}
    for sleeping in (True, False):
        env = gym.make("ShelfSort-v0", sleeping=sleeping).unwrapped
        env.set_scene([(box(), 0, 0.20, 0.0, 0.0), (box(0.05, 0.05, 0.07), 1, 0.20, -0.07, 0.0),
                       (box(), 2, 0.32, 0.20, 0.0)], REGIONS)
        env.step(action_at(env, "push_right", 0.20, 0.05))  # blade -> box 0 -> box 1
        pushed = env.world.positions().copy()
        env.step(action_at(env, "pick", *pushed[1][:2]))
        finals[sleeping] = (pushed, env.world.positions().copy())
        env.close()
    pushed, placed = finals[True]
    assert pushed[1][1] < -0.11  # the push really reached the second box through the first
    assert placed[1][0] > 0.3  # and the pick really moved it
    for a, b in zip(finals[True], finals[False]):
        assert np.abs(a - b).max() < 0.002, (a, b)
