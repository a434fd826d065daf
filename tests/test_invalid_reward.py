"""`ShelfSortEnv(invalid_reward=r)`: a step that ends the episode invalid (an object fell out) gets r
instead of the paper's -10, every other reward is unchanged, and the privileged lookahead still
tells an invalid probe from a valid one under it (real physics, crafted scenes)."""

import gymnasium as gym
import pytest

from shelf_env import params
from shelf_env.privileged.lookahead import probe_step
from shelf_env.training.config import TrainConfig
from tests.conftest import REGIONS, action_at, box

# the fall of tests/test_primitives.py: the tall object's pick drags the light one out of the opening
FALL_SCENE = [(box(0.05, 0.05, 0.17, mass=0.3), 1, 0.25, 0.0, 0.0),
              (box(0.04, 0.04, 0.06, mass=0.05), 2, 0.03, 0.0, 0.0)]


@pytest.fixture
def harsh_env():
    e = gym.make("ShelfSort-v0", num_objects=3, invalid_reward=-100.0).unwrapped
    e.reset(seed=0)
    yield e
    e.close()


def test_a_fall_gets_the_invalid_reward_and_other_steps_keep_the_papers(harsh_env, env):
    assert env.invalid_reward == params.REWARD_INVALID == -10.0  # the default is the paper's Eq. 2
    for e, expected in ((env, params.REWARD_INVALID), (harsh_env, -100.0)):
        e.set_scene(FALL_SCENE, REGIONS)
        _, reward, terminated, _, info = e.step(action_at(e, "pick", 0.25, 0.0))
        assert info["fell"] and terminated and reward == expected
    # a valid step that sorts nothing: -1; one that sorts the scene: 0
    harsh_env.set_scene([(box(), 0, 0.30, 0.0, 0.0), (box(), 1, 0.30, 0.21, 0.0)], REGIONS)
    _, reward, terminated, _, _ = harsh_env.step(action_at(harsh_env, "push_right", 0.05, -0.25))
    assert reward == params.REWARD_STEP and not terminated
    harsh_env.set_scene([(box(), 0, 0.30, 0.21, 0.0), (box(0.05, 0.05, 0.07), 1, 0.15, -0.20, 0.3)], REGIONS)
    _, reward, terminated, _, info = harsh_env.step(action_at(harsh_env, "pick", 0.15, -0.20))
    assert info["is_success"] and terminated and reward == params.REWARD_SORTED


def test_the_progress_bonus_does_not_reach_an_invalid_step():
    e = gym.make("ShelfSort-v0", num_objects=3, invalid_reward=-30.0, progress_reward=1.0).unwrapped
    try:
        e.reset(seed=0)
        e.set_scene(FALL_SCENE, REGIONS)
        _, reward, terminated, _, info = e.step(action_at(e, "pick", 0.25, 0.0))
        assert info["fell"] and terminated and reward == -30.0
    finally:
        e.close()


def test_the_lookahead_reads_validity_from_the_flags_not_the_reward(harsh_env):
    harsh_env.set_scene(FALL_SCENE, REGIONS)
    fall = probe_step(harsh_env, action_at(harsh_env, "pick", 0.25, 0.0))
    assert fall.reward == -100.0 and fall.fell and not fall.valid
    safe = probe_step(harsh_env, action_at(harsh_env, "pick", 0.03, 0.0))  # the light front object alone
    assert not safe.fell and safe.valid


@pytest.mark.parametrize("bad", [0.0, 5.0, float("nan"), float("-inf"), True, "-100"])
def test_bad_invalid_reward_is_refused_by_name(bad):
    with pytest.raises(ValueError, match="invalid_reward must be a finite number < 0"):
        gym.make("ShelfSort-v0", invalid_reward=bad)
    with pytest.raises(ValueError, match="TrainConfig.invalid_reward must be a finite number < 0"):
        TrainConfig(invalid_reward=bad).check()


def test_train_config_passes_invalid_reward_to_the_training_env_only_and_to_the_zoo_file():
    from shelf_env.training.config import PRESETS, make_env, make_unsupervised_training_env
    from shelf_env.training.zoo import ENV_ID, zoo_hyperparams

    config = TrainConfig(invalid_reward=-100.0, start_objects=1)
    training, check = make_unsupervised_training_env(config), make_env(config)
    try:
        assert training.unwrapped.invalid_reward == -100.0
        assert check.unwrapped.invalid_reward == params.REWARD_INVALID  # greedy checks and evaluations
    finally:
        training.close()
        check.close()
    assert zoo_hyperparams(config)[ENV_ID]["env_kwargs"]["invalid_reward"] == -100.0
    assert zoo_hyperparams(PRESETS["p_s"])[ENV_ID]["env_kwargs"]["invalid_reward"] == params.REWARD_INVALID
    assert TrainConfig.from_dict(config.to_dict()).invalid_reward == -100.0
