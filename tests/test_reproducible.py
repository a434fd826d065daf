"""History-free episodes: (scene, actions) alone decide what an episode observes and earns.

Evaluation cells, demonstrations and "the same scenes for every policy" replay episodes in envs
that have run other episodes before, beside other envs in the same process. Each test records an
episode in a fresh env, runs unrelated episodes (other seeds, other N, a YCB env in the same
process), replays the recorded actions and asks for bit-identical observations, rewards and infos.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from tests.conftest import REGIONS, box


def _strip(info: dict) -> dict:
    """An info with its arrays turned into bytes, so two infos compare with ==."""
    out = {}
    for key, value in info.items():
        if isinstance(value, np.ndarray):
            out[key] = (value.dtype.str, value.shape, value.tobytes())
        elif isinstance(value, dict):
            out[key] = _strip(value)
        else:
            out[key] = value
    return out


def _play(env, first: tuple[np.ndarray, dict], actions: list[int] | None, rng: np.random.Generator | None,
          max_actions: int = 6) -> tuple[list[int], list[np.ndarray], list[tuple]]:
    """Step ``actions`` (or masked random ones drawn from ``rng``) from an episode's first (obs, info)."""
    obs, info = first
    chosen: list[int] = []
    observations, outcomes = [obs], [_strip(info)]
    for i in range(max_actions if actions is None else len(actions)):
        if actions is None:
            action = int(rng.choice(np.flatnonzero(env.action_masks())))
        else:
            action = actions[i]
        obs, reward, terminated, truncated, info = env.step(action)
        chosen.append(action)
        observations.append(obs)
        outcomes.append((reward, terminated, truncated, _strip(info)))
        if terminated or truncated:
            break
    return chosen, observations, outcomes


def _other_episodes(env, other: gym.Env) -> None:
    """Unrelated work in the same env (other seeds and N) and in a second env of the same process."""
    rng = np.random.default_rng(5)
    for seed, n in ((11, 5), (12, 1), (13, 4)):
        _play(env, env.reset(seed=seed, options={"num_objects": n}), None, rng, max_actions=3)
        _play(other, other.reset(seed=seed), None, rng, max_actions=2)
    env.set_num_objects(3)


def _assert_same(a: tuple, b: tuple) -> None:
    _, obs_a, out_a = a
    _, obs_b, out_b = b
    assert len(obs_a) == len(obs_b)
    for i, (x, y) in enumerate(zip(obs_a, obs_b)):
        assert np.array_equal(x, y), f"observation {i} differs"
    assert out_a == out_b


def test_reset_episode_replays_bit_identically_after_other_episodes():
    env = gym.make("ShelfSort-v0", num_objects=3).unwrapped
    other = gym.make("ShelfSort-v0", num_objects=4, object_set="ycb").unwrapped
    try:
        recorded = _play(env, env.reset(seed=8080), None, np.random.default_rng(0))
        assert len(recorded[0]) >= 2  # a real episode, not a one-step one
        _other_episodes(env, other)
        replayed = _play(env, env.reset(seed=8080), recorded[0], None)
        _assert_same(recorded, replayed)
    finally:
        env.close()
        other.close()


def test_set_scene_episode_replays_bit_identically_after_other_episodes():
    scene = [(box(), 0, 0.30, 0.0, 0.0), (box(0.05, 0.05, 0.07), 1, 0.20, 0.15, 0.4), (box(), 2, 0.12, -0.2, 0.0)]
    env = gym.make("ShelfSort-v0", num_objects=3).unwrapped
    other = gym.make("ShelfSort-v0", num_objects=2, object_set="ycb").unwrapped
    try:
        recorded = _play(env, env.set_scene(scene, REGIONS), None, np.random.default_rng(1), max_actions=4)
        _other_episodes(env, other)
        replayed = _play(env, env.set_scene(scene, REGIONS), recorded[0], None)
        _assert_same(recorded, replayed)
    finally:
        env.close()
        other.close()

