"""`shelf_env.world.task`: the task's rules on crafted worlds (sorted, relabel, fell), without a step."""

import pybullet as pb
import pytest

from shelf_env import params
from shelf_env.world import task
from tests.conftest import REGIONS, box

# REGIONS: class 0 left (y > 0.12), class 1 middle, class 2 right (y < -0.12); all full depth


def test_sorted_scene(env):
    env.set_scene([(box(), 0, 0.2, 0.2, 0.0), (box(), 1, 0.2, 0.0, 0.0)], REGIONS)
    j = task.judge(env.world)
    assert j.valid and j.sorted and not j.fell and not j.relabel
    assert j.reward == params.REWARD_SORTED and j.terminated and j.is_success(2) and not j.is_success(3)


def test_every_object_in_a_wrong_region_is_relabelled_not_sorted(env):
    env.set_scene([(box(), 1, 0.2, 0.2, 0.0), (box(), 0, 0.2, 0.0, 0.0)], REGIONS)
    j = task.judge(env.world)
    assert j.valid and not j.sorted and j.relabel
    assert j.reward == params.REWARD_STEP and not j.terminated and not j.is_success(2)
    assert j.region.tolist() == [0, 1] and j.classes.tolist() == [1, 0]


def test_an_object_outside_is_a_fall_and_invalid(env):
    env.set_scene([(box(), 0, 0.2, 0.2, 0.0), (box(), 1, 0.2, 0.0, 0.0)], REGIONS)
    pb.resetBasePositionAndOrientation(env.world.objects[1].uid, (-0.3, 0.0, 0.04), (0, 0, 0, 1),
                                       physicsClientId=env.client)
    j = task.judge(env.world)
    assert j.fell and not j.valid and not j.sorted and not j.relabel
    assert j.inside.tolist() == [True, False] and len(j.region) == 1
    assert j.reward == params.REWARD_INVALID and j.terminated and not j.is_success(2)


def test_a_moving_object_is_not_at_rest_so_invalid(env):
    env.set_scene([(box(), 0, 0.2, 0.2, 0.0)], REGIONS)
    pb.resetBaseVelocity(env.world.objects[0].uid, (0.3, 0.0, 0.0), (0, 0, 0), physicsClientId=env.client)
    j = task.judge(env.world)
    assert not j.fell and not j.valid and j.reward == pytest.approx(params.REWARD_INVALID)
