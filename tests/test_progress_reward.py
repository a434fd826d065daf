"""`ShelfSortEnv(progress_reward=c)`: a valid step gains c per object it sorts and loses c per
object it unsorts, invalid steps keep -10, the relabelled transition gains c per object whose region
changed; and 0 is the paper's reward, bit for bit (real physics, crafted scenes)."""

import gymnasium as gym
import pytest

from shelf_env import params
from shelf_env.training.config import TrainConfig
from tests.conftest import REGIONS, action_at, box


@pytest.fixture
def progress_env():
    e = gym.make("ShelfSort-v0", num_objects=3, progress_reward=1.5).unwrapped
    e.reset(seed=0)
    yield e
    e.close()


def test_sorting_the_last_object_gains_the_bonus(progress_env, env):
    # green (class 0) sorted on the left, yellow (class 1) in blue's region: picking yellow sorts it
    scene = [(box(), 0, 0.30, 0.21, 0.0), (box(0.05, 0.05, 0.07), 1, 0.15, -0.20, 0.3)]
    for e, bonus in ((env, 0.0), (progress_env, 1.5)):
        e.set_scene(scene, REGIONS)
        _, reward, terminated, _, info = e.step(action_at(e, "pick", 0.15, -0.20))
        assert info["is_success"] and terminated and info["num_sorted"] == 2
        assert reward == params.REWARD_SORTED + bonus


def test_relabelled_transition_gains_the_bonus_of_the_objects_whose_region_changed(progress_env, env):
    # green in yellow's region (wrong), yellow in blue's (wrong): picking yellow puts it in its own
    # region, so every object is in some region, one of them not its own: a relabelled transition
    scene = [(box(), 0, 0.30, 0.0, 0.0), (box(0.05, 0.05, 0.07), 1, 0.15, -0.20, 0.3)]
    for e, bonus in ((env, 0.0), (progress_env, 1.5)):
        e.set_scene(scene, REGIONS)
        _, reward, terminated, _, info = e.step(action_at(e, "pick", 0.15, -0.20))
        assert not terminated and info["num_sorted"] == 1
        assert reward == params.REWARD_STEP + bonus  # yellow sorted: one object
        assert info["relabelled"]["reward"] == params.REWARD_SORTED + bonus  # yellow's region changed


def test_a_step_that_sorts_nothing_and_an_invalid_step_keep_the_papers_reward(progress_env):
    progress_env.set_scene([(box(), 0, 0.30, 0.0, 0.0), (box(), 1, 0.30, 0.21, 0.0)], REGIONS)
    _, reward, _, _, info = progress_env.step(action_at(progress_env, "push_right", 0.05, -0.25))
    assert reward == params.REWARD_STEP and info["num_sorted"] == 0
    assert info["relabelled"]["reward"] == params.REWARD_SORTED  # no region changed
    # the fall of tests/test_primitives.py: the tall object's pick drags the light one out
    tall, light = box(0.05, 0.05, 0.17, mass=0.3), box(0.04, 0.04, 0.06, mass=0.05)
    progress_env.set_scene([(tall, 1, 0.25, 0.0, 0.0), (light, 2, 0.03, 0.0, 0.0)], REGIONS)
    _, reward, terminated, _, info = progress_env.step(action_at(progress_env, "pick", 0.25, 0.0))
    assert info["fell"] and terminated and reward == params.REWARD_INVALID


def test_unsorting_an_object_costs_the_bonus(progress_env):
    # yellow alone, sorted in the middle; a push-right from its left face takes it ~8 cm to the
    # right, out of its region (y in -0.09..0.09) into none
    progress_env.set_scene([(box(), 1, 0.20, -0.05, 0.0), (box(), 0, 0.30, 0.21, 0.0)], REGIONS)
    assert progress_env.world.in_own_region()[0]
    _, reward, _, _, info = progress_env.step(action_at(progress_env, "push_right", 0.20, 0.0))
    assert not progress_env.world.in_own_region()[0] and info["num_sorted"] == 1
    assert reward == params.REWARD_STEP - 1.5


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), True, "1"])
def test_bad_progress_reward_is_refused_by_name(bad):
    with pytest.raises(ValueError, match="progress_reward must be a finite number >= 0"):
        gym.make("ShelfSort-v0", progress_reward=bad)
    with pytest.raises(ValueError, match="TrainConfig.progress_reward must be a finite number >= 0"):
        TrainConfig(progress_reward=bad).check()


def test_train_config_passes_progress_reward_to_the_training_env_only_and_to_the_zoo_file():
    from shelf_env.training.config import PRESETS, make_env, make_unsupervised_training_env
    from shelf_env.training.zoo import ENV_ID, zoo_hyperparams

    config = TrainConfig(progress_reward=0.5, start_objects=1)
    training, check = make_unsupervised_training_env(config), make_env(config)
    try:
        assert training.unwrapped.progress_reward == 0.5
        assert check.unwrapped.progress_reward == 0.0  # greedy checks and evaluations: the paper's
    finally:
        training.close()
        check.close()
    assert zoo_hyperparams(config)[ENV_ID]["env_kwargs"]["progress_reward"] == 0.5
    assert zoo_hyperparams(PRESETS["p_s"])[ENV_ID]["env_kwargs"]["progress_reward"] == 0.0
    assert TrainConfig.from_dict(config.to_dict()).progress_reward == 0.5
