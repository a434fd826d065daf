"""sb3-contrib-style contract tests of PixelDoubleDQN on ShelfSort-v0: both action layouts (P+S and
the pick-only S), one and two envs; check_env, learn, save/load round trips, predict on single and
batched observations (with and without masks)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.env_util import make_vec_env

from sb3_pixeldqn import PICK_AND_PUSH_MAPS, PICK_ONLY_MAPS, PixelDoubleDQN
from sb3_pixeldqn.pixel_dqn import get_action_masks

LAYOUTS = {"p_s": (("pick", "push"), PICK_AND_PUSH_MAPS), "s": (("pick",), PICK_ONLY_MAPS)}
ENV_KW = dict(num_objects=2, pixel_size=0.02)  # 20 x 30 cells: small and fast


def make(layout: str, n_envs: int):
    primitives, maps = LAYOUTS[layout]
    env = make_vec_env("ShelfSort-v0", n_envs=n_envs, seed=0, env_kwargs=dict(primitives=primitives, **ENV_KW))
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=maps, widths=(4, 8, 8)), learning_starts=4,
                           batch_size=4, buffer_size=64, seed=0)
    return env, model


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_check_env_passes_on_both_layouts(layout):
    # 1 cm cells: below 36 x 36 SB3 warns that its CnnPolicy cannot take the image
    env = gym.make("ShelfSort-v0", primitives=LAYOUTS[layout][0], num_objects=2, pixel_size=0.01).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, warn=True)
    env.close()
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize("n_envs", [1, 2])
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_learn_save_load_round_trip(tmp_path, layout, n_envs):
    env, model = make(layout, n_envs)
    model.learn(8)
    assert model.num_timesteps >= 8 and model.replay_buffer.size() > 0
    obs = env.reset()
    masks = get_action_masks(env)
    assert masks.shape == (n_envs, env.action_space.n)
    before, _ = model.predict(obs, deterministic=True, action_masks=masks)
    q_before = model.policy.q_map_values(obs)
    model.save(tmp_path / "m.zip")
    model.save_replay_buffer(tmp_path / "r.pkl")
    loaded = PixelDoubleDQN.load(tmp_path / "m.zip", env=env)
    loaded.load_replay_buffer(tmp_path / "r.pkl")
    after, _ = loaded.predict(obs, deterministic=True, action_masks=masks)
    assert np.array_equal(before, after) and before.shape == (n_envs,)
    assert np.allclose(q_before, loaded.policy.q_map_values(obs))
    for p, q in zip(model.policy.state_dict().values(), loaded.policy.state_dict().values()):
        assert th.equal(p, q)
    assert loaded.replay_buffer.size() == model.replay_buffer.size()
    assert loaded.policy.maps == model.policy.maps and loaded.action_space == env.action_space
    loaded.learn(4, reset_num_timesteps=False)  # keeps training after a load
    env.close()


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_predict_on_single_and_batched_observations(layout):
    env, model = make(layout, 2)
    obs = env.reset()
    masks = get_action_masks(env)
    single, state = model.predict(obs[0], deterministic=True)
    assert state is None and np.ndim(single) == 0 and 0 <= int(single) < env.action_space.n
    batch, _ = model.predict(obs, deterministic=True)
    assert batch.shape == (2,) and int(batch[0]) == int(single)
    masked, _ = model.predict(obs, deterministic=True, action_masks=masks)
    assert all(masks[i, a] for i, a in enumerate(masked))
    single_masked, _ = model.predict(obs[1], deterministic=True, action_masks=masks[1])
    assert int(single_masked) == int(masked[1])
    q = model.policy.q_map_values(obs[0])
    assert q.shape == (len(LAYOUTS[layout][1]), *obs.shape[2:]) and q.dtype == np.float32
    assert int(single) == int(np.argmax(q.reshape(-1)))
    env.close()
