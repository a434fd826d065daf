"""ShelfSort-v0's Gymnasium contract: spaces, seeding, bad input, body bookkeeping."""

import warnings

import gymnasium as gym
import numpy as np
import pybullet as pb
import pytest
from stable_baselines3.common.env_checker import check_env

from shelf_env.env import ShelfSortEnv, map_names
from tests.conftest import REGIONS, box


def test_check_env_passes_without_warnings():
    env = gym.make("ShelfSort-v0", num_objects=2).unwrapped
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, warn=True)
    env.close()
    assert [str(w.message) for w in caught] == []


def test_spaces_and_map_layout():
    env = ShelfSortEnv(num_objects=1)
    assert env.observation_space.shape == (4, 80, 120) and env.observation_space.dtype == np.uint8
    assert env.action_space.n == 3 * 80 * 120
    assert env.map_names == ["pick", "push_left", "push_right"]
    env.close()
    s = ShelfSortEnv(num_objects=1, primitives=("pick",), pixel_size=0.01)
    assert s.observation_space.shape == (4, 40, 60) and s.action_space.n == 40 * 60
    assert map_names(("pick",)) == ["pick"]
    s.close()


def test_same_seed_gives_identical_observation_sequence():
    def rollout():
        env = gym.make("ShelfSort-v0", num_objects=3).unwrapped
        obs, _ = env.reset(seed=7)
        seq = [obs]
        rng = np.random.default_rng(1)
        for _ in range(3):
            obj_cells = np.argwhere(env._semantic[0] >= 0)
            r, c = obj_cells[rng.integers(len(obj_cells))]
            a = env.codec.encode(env.map_names[int(rng.integers(3))], int(r), int(c))
            obs, *_ = env.step(a)
            seq.append(obs)
        again, _ = env.reset(seed=7)
        env.close()
        return seq, again

    a, a_again = rollout()
    b, _ = rollout()
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert np.array_equal(a[0], a_again)  # the same env re-seeded starts from the same scene
    assert not all(np.array_equal(a[0], x) for x in a[1:])  # the actions did change the scene


@pytest.mark.parametrize("kwargs, match", [
    ({"num_objects": 0}, "num_objects"),
    ({"num_objects": 15}, r"num_objects must be in \[1, 14\]"),
    ({"num_objects": "3"}, "num_objects must be an integer"),
    ({"object_set": "shoes"}, "unknown object_set"),
    ({"primitives": ("grasp",)}, "primitives"),
    ({"primitives": ()}, "primitives"),
    ({"render_mode": "human"}, "render_mode"),
    ({"max_actions": 0}, "max_actions"),
    ({"min_num_objects": 0}, r"min_num_objects must be in \[1, 14\]"),
    ({"min_num_objects": 2.0}, "min_num_objects must be an integer"),
])
def test_bad_constructor_arguments_raise_clear_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ShelfSortEnv(**kwargs)


def test_bad_step_reset_arguments_raise_clear_errors(env):
    n = env.action_space.n
    for bad, match in [(-1, "out of range"), (n, "out of range"), (1.5, "integer"), ("3", "integer"),
                       (np.array([1, 2]), "single integer")]:
        with pytest.raises(ValueError, match=match):
            env.step(bad)
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed="abc")
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed=-1)
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"n_objects": 3})
    with pytest.raises(ValueError, match="num_objects"):
        env.set_num_objects(99)
    # the env still works after all of that
    obs, info = env.reset(seed=1, options={"num_objects": 4})
    assert info["num_objects"] == 4 and obs.shape == (4, 80, 120)
    env.step(np.int64(5))


def test_set_num_objects_applies_from_next_reset(env):
    env.set_num_objects(5)
    _, info = env.reset(seed=3)
    assert info["num_objects"] == 5 and len(env.world.objects) == 5


def test_min_num_objects_draws_each_episodes_n_from_the_seeded_stream():
    def sizes(env: ShelfSortEnv, seed: int, count: int) -> list[int]:
        first = env.reset(seed=seed)[1]["num_objects"]
        return [first] + [env.reset()[1]["num_objects"] for _ in range(count - 1)]

    mixed = ShelfSortEnv(num_objects=5, min_num_objects=2, pixel_size=0.02)
    drawn = sizes(mixed, 7, 24)
    assert set(drawn) == {2, 3, 4, 5}  # both ends, and nothing outside them
    assert len(mixed.world.objects) == drawn[-1]  # the episode's N is what it spawned
    again = ShelfSortEnv(num_objects=5, min_num_objects=2, pixel_size=0.02)
    assert sizes(again, 7, 24) == drawn  # the seed fixes the sizes, as it fixes the scenes
    mixed.set_num_objects(8)  # a curriculum moves the upper end
    assert set(sizes(mixed, 8, 30)) == set(range(2, 9))
    mixed.set_num_objects(1)  # a stage below the lower end plays the stage's N
    assert sizes(mixed, 9, 3) == [1, 1, 1]
    # without it, every episode has num_objects objects and the seeded scenes are the old ones
    plain, same = ShelfSortEnv(num_objects=5, pixel_size=0.02), ShelfSortEnv(num_objects=5, pixel_size=0.02,
                                                                             min_num_objects=5)
    assert sizes(plain, 3, 4) == [5, 5, 5, 5] and plain.min_num_objects is None
    assert sizes(same, 3, 1) == [5]
    for e in (mixed, again, plain, same):
        e.close()


def test_render_gives_a_picture_and_close_releases_client():
    env = ShelfSortEnv(num_objects=2, render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8 and img.std() > 10
    client = env.client
    env.close()
    assert not pb.isConnected(client)
    env.close()  # idempotent


def _body_count_stays_constant(resets: int):
    env = ShelfSortEnv(num_objects=1)
    env.reset(seed=0)
    static = pb.getNumBodies(physicsClientId=env.client) - len(env.world.objects)
    rng = np.random.default_rng(0)
    for i in range(resets):
        n = int(rng.integers(1, 15))
        env.reset(seed=i, options={"num_objects": n})
        assert pb.getNumBodies(physicsClientId=env.client) == static + n
    env.close()


def test_resets_keep_body_count_constant():
    _body_count_stays_constant(40)


@pytest.mark.slow
def test_thousand_resets_keep_body_count_constant():
    _body_count_stays_constant(1000)


def test_action_masks_mark_object_cells_and_pushes_that_reach_them(env):
    env.set_scene([(box(0.06, 0.06, 0.08), 0, 0.25, 0.0, 0.0)], REGIONS)
    mask = env.action_masks().reshape(3, env.rows, env.cols)
    assert mask.dtype == bool and mask.size == env.action_space.n
    seen = env._semantic[0] >= 0
    assert np.array_equal(mask[0], seen)
    rows, cols = np.nonzero(seen)
    r = int(np.median(rows))
    left_edge, right_edge = cols.min(), cols.max()
    reach = round(0.08 / env.camera.pixel_size)
    # push-left moves towards col 0: it meets the object if it starts right of it within reach
    assert mask[1, r, right_edge + reach] and not mask[1, r, right_edge + reach + 1]
    assert mask[2, r, left_edge - reach] and not mask[2, r, left_edge - reach - 1]
    assert not mask[1, r, left_edge - 1] and not mask[2, r, right_edge + 1]
    assert not mask[:, : rows.min() - 2].any()


def test_set_num_objects_mid_episode_keeps_the_episode_n(env):
    env.reset(seed=1, options={"num_objects": 2})
    env.set_num_objects(5)
    obs, reward, terminated, truncated, info = env.step(0)
    assert info["num_objects"] == 2
    env.reset(seed=2)
    assert len(env.world.objects) == 5


@pytest.mark.parametrize("pixel_size", [0.01, 0.005])
def test_masks_read_from_the_observation_alone_equal_the_envs(pixel_size):
    from shelf_env.camera.heightmap import observation_masks

    env = gym.make("ShelfSort-v0", num_objects=6, pixel_size=pixel_size).unwrapped
    rng = np.random.default_rng(0)
    try:
        for seed in range(3):
            obs, _ = env.reset(seed=seed)
            for _ in range(3):  # the scene as it starts and after a few allowed actions
                mask = env.action_masks()
                assert mask.sum() < mask.size  # objects are visible: the mask says something
                assert np.array_equal(observation_masks(obs, pixel_size, env.map_names), mask)
                obs, _, terminated, truncated, _ = env.step(int(rng.choice(np.flatnonzero(mask))))
                if terminated or truncated:
                    break
    finally:
        env.close()
