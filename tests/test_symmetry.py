"""The cabinet's symmetries map real transitions to transitions the env itself produces.

For each transform: play an action in a crafted scene, play the transformed action in the
transformed scene (mirrored across the width, or with the classes renamed), and check that the
second transition is the transform of the first: observations, reward (sorted stays sorted),
masks, and where the objects went.
"""

import gymnasium as gym
import numpy as np
import pytest
from conftest import REGIONS, action_at, box

from shelf_env.actions import ActionCodec
from shelf_env.symmetry import MirrorWidth, PermuteClasses, cabinet_symmetries
from shelf_env.world.cabinet import Region


def mirrored_regions(regions):
    return [Region(r.x0, r.x1, -r.y1, -r.y0) for r in regions]


def step_scene(env, objects, regions, action_of):
    obs, _ = env.set_scene(objects, regions)
    mask = env.action_masks()
    action = action_of(env)
    next_obs, reward, terminated, _, info = env.step(action)
    return obs, mask, action, next_obs, reward, terminated, env.world.positions(), env.action_masks()


@pytest.fixture(scope="module")
def shelf():
    env = gym.make("ShelfSort-v0", num_objects=2, pixel_size=0.01).unwrapped
    env.reset(seed=0)
    yield env
    env.close()


def close_share(a: np.ndarray, b: np.ndarray) -> float:
    """Share of heightmap cells whose 4 channels agree (colour exactly, height within 2 levels)."""
    same_colour = (a[:3] == b[:3]).all(axis=0)
    same_height = np.abs(a[3].astype(int) - b[3].astype(int)) <= 2
    return float((same_colour & same_height).mean())


def test_mirror_of_a_push_is_the_mirrored_push(shelf):
    mirror = MirrorWidth.for_env(shelf, p=1.0)
    scene = [(box(0.06, 0.05, 0.08), 0, 0.22, -0.02, 0.2), (box(0.05, 0.05, 0.10), 2, 0.12, 0.17, 0.0)]
    a = step_scene(shelf, scene, REGIONS, lambda e: action_at(e, "push_left", 0.22, -0.10))
    m_scene = [(spec, cls, x, -y, -yaw) for spec, cls, x, y, yaw in scene]
    b = step_scene(shelf, m_scene, mirrored_regions(REGIONS), lambda e: action_at(e, "push_right", 0.22, 0.10))
    obs_a, mask_a, act_a, next_a, reward_a, _, pos_a, next_mask_a = a
    obs_b, mask_b, act_b, next_b, reward_b, _, pos_b, next_mask_b = b
    assert act_b == mirror.action(act_a)
    # the camera's rasterisation is not bit-exact under mirroring: object edges may differ by a cell
    assert close_share(obs_b, mirror.observation(obs_a)) >= 0.99
    assert (mask_b == mirror.mask(mask_a)).mean() >= 0.99
    assert reward_a == reward_b == -1.0
    moved = np.abs(pos_a[0, 1] - (-0.02))
    assert moved > 0.02  # the push really moved the box ...
    assert np.allclose(pos_b[:, :2], pos_a[:, :2] * [1, -1], atol=0.005)  # ... and the mirror moved its mirror image
    assert close_share(next_b, mirror.observation(next_a)) >= 0.98
    assert (next_mask_b == mirror.mask(next_mask_a)).mean() >= 0.99


def test_mirror_keeps_sorted_sorted(shelf):
    # one object of class 0 outside its (left) region: a pick puts it there and sorts the scene
    mirror = MirrorWidth.for_env(shelf, p=1.0)
    scene = [(box(0.05, 0.05, 0.06), 0, 0.15, -0.02, 0.0)]
    a = step_scene(shelf, scene, REGIONS, lambda e: action_at(e, "pick", 0.15, -0.02))
    b = step_scene(shelf, [(scene[0][0], 0, 0.15, 0.02, 0.0)], mirrored_regions(REGIONS),
                   lambda e: action_at(e, "pick", 0.15, 0.02))
    assert b[2] == mirror.action(a[2])
    assert a[4] == b[4] == 0.0 and a[5] and b[5]  # both sorted, both terminal


def test_permuting_classes_is_the_same_scene_with_renamed_classes(shelf):
    permute = PermuteClasses()
    perm = [2, 0, 1]  # class k is shown as class perm[k]
    scene = [(box(0.06, 0.05, 0.08), 0, 0.20, -0.20, 0.0), (box(0.05, 0.06, 0.07), 1, 0.30, 0.20, 0.3),
             (box(0.05, 0.05, 0.09), 2, 0.10, 0.0, 0.0)]
    a = step_scene(shelf, scene, REGIONS, lambda e: action_at(e, "pick", 0.20, -0.20))
    p_scene = [(spec, perm[cls], x, y, yaw) for spec, cls, x, y, yaw in scene]
    p_regions = [None] * 3
    for k, region in enumerate(REGIONS):
        p_regions[perm[k]] = region
    b = step_scene(shelf, p_scene, p_regions, lambda e: action_at(e, "pick", 0.20, -0.20))
    assert np.array_equal(b[0], permute.observation(a[0], perm))
    assert np.array_equal(b[1], a[1])  # masks are blind to classes
    assert b[4] == a[4] and b[5] == a[5]
    assert np.allclose(b[6], a[6], atol=0.002)  # the picked object went to the same place
    assert close_share(b[3], permute.observation(a[3], perm)) >= 0.99
    assert not np.array_equal(a[3], permute.observation(a[3], perm))  # it did recolour something


def test_transforms_keep_layouts_and_are_involutions_where_they_should_be(shelf):
    obs, _ = shelf.reset(seed=5)
    mask = shelf.action_masks()
    rng = np.random.default_rng(0)
    for transform in cabinet_symmetries(shelf):
        o, a, n, m = transform(obs, 123, obs, mask, rng)
        assert o.shape == obs.shape and o.dtype == obs.dtype and m.shape == mask.shape and m.dtype == bool
        assert 0 <= a < shelf.action_space.n
    mirror = MirrorWidth.for_env(shelf, p=1.0)
    for action in (0, 57, shelf.rows * shelf.cols + 5, shelf.action_space.n - 1):
        assert mirror.action(mirror.action(action)) == action
    assert np.array_equal(mirror.mask(mirror.mask(mask)), mask)
    with pytest.raises(ValueError, match="permutation of 0..2"):
        PermuteClasses().observation(obs, [0, 0, 1])
    with pytest.raises(ValueError, match="knows the maps"):
        MirrorWidth(ActionCodec(("pick", "rotate"), 4, 6, 0.01))
