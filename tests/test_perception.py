"""Perception noise (`shelf_env.conditions.perception_noise`): each kind does what it says, noise is reproducible per
seed, zero noise is bit-identical to none, bad settings are a clear ValueError."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from shelf_env.camera.heightmap import CLASS_RGB
from shelf_env.conditions.perception_noise import PerceptionNoise
from tests.conftest import REGIONS, box

SCENE = [(box(), 0, 0.30, -0.20, 0.0), (box(), 1, 0.25, 0.0, 0.0), (box(), 2, 0.15, 0.20, 0.0)]


def crafted(noise):
    env = gym.make("ShelfSort-v0", num_objects=3, perception_noise=noise).unwrapped
    env.reset(seed=4)  # seeds the env's generator, which seeds the noise of the next episode
    obs, _ = env.set_scene(SCENE, REGIONS)
    return env, obs


def class_cells(obs: np.ndarray) -> list[int]:
    rgb = obs[:3].transpose(1, 2, 0)
    return [int((rgb == CLASS_RGB[k]).all(-1).sum()) for k in range(3)]


def test_each_kind_of_noise_on_a_crafted_scene():
    env, clean = crafted(None)
    env.close()
    assert min(class_cells(clean)) > 20  # every object visible
    env, dropped = crafted({"dropout": 1.0})
    assert class_cells(dropped) == [0, 0, 0]
    assert np.array_equal(dropped[3], clean[3])  # depth was measured all the same
    assert env.action_masks().all()  # nothing visible: the mask has nothing to say
    env.close()
    env, flipped = crafted({"class_flip": 1.0})
    env.close()
    assert sum(class_cells(flipped)) == sum(class_cells(clean)) and class_cells(flipped) != class_cells(clean)
    env, parts = crafted({"part_dropout": 1.0})
    env.close()
    assert all(0 < p < c for p, c in zip(class_cells(parts), class_cells(clean)))
    env, noisy = crafted({"depth_sigma": 0.005})
    env.close()
    assert np.array_equal(noisy[:3], clean[:3]) and not np.array_equal(noisy[3], clean[3])


def rollout(noise, seed: int, actions: list[int] | None = None, n: int = 3):
    env = gym.make("ShelfSort-v0", num_objects=4, perception_noise=noise).unwrapped
    obs, info = env.reset(seed=seed)
    out, chosen = [obs], []
    rng = np.random.default_rng(0)
    for i in range(n if actions is None else len(actions)):
        action = int(rng.choice(np.flatnonzero(env.action_masks()))) if actions is None else actions[i]
        obs, reward, terminated, truncated, info = env.step(action)
        out.append(obs)
        chosen.append(action)
        if terminated or truncated:
            break
    env.close()
    return out, chosen


def test_noise_is_reproducible_per_seed_and_differs_across_seeds():
    noise = {"dropout": 0.3, "part_dropout": 0.3, "class_flip": 0.3, "depth_sigma": 0.003}
    first, actions = rollout(noise, seed=11)
    again, _ = rollout(noise, seed=11, actions=actions)
    assert all(np.array_equal(a, b) for a, b in zip(first, again)) and len(first) == len(again)
    clean, _ = rollout(None, seed=11, actions=actions[:1])
    assert not np.array_equal(first[0], clean[0])


@pytest.mark.parametrize("zero", [{}, {"dropout": 0.0, "part_dropout": 0.0, "class_flip": 0.0, "depth_sigma": 0.0},
                                  PerceptionNoise()])
def test_zero_noise_is_bit_identical_to_none(zero):
    none, actions = rollout(None, seed=5)
    same, _ = rollout(zero, seed=5, actions=actions)
    assert len(none) == len(same) and all(np.array_equal(a, b) for a, b in zip(none, same))


@pytest.mark.parametrize("bad, match", [
    ({"dropout": 1.5}, "dropout must be a probability in \\[0, 1\\]"),
    ({"class_flip": -0.1}, "class_flip must be a probability"),
    ({"part_dropout": True}, "part_dropout must be a probability"),
    ({"depth_sigma": -0.001}, "depth_sigma must be a finite number of metres >= 0"),
    ({"depth_sigma": float("nan")}, "depth_sigma"),
    ({"dropuot": 0.1}, "unknown perception_noise keys \\['dropuot'\\]"),
    (0.1, "must be a dict, a PerceptionNoise or None"),
])
def test_bad_noise_settings(bad, match):
    with pytest.raises(ValueError, match=match):
        gym.make("ShelfSort-v0", num_objects=1, perception_noise=bad)
