"""FCNPolicy: map layout, shapes, rotations, selective evaluation, bad spaces."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from pixel_envs import FindTheSquareEnv

from sb3_pixeldqn import FCNPolicy, PixelDoubleDQN
from sb3_pixeldqn.networks import ResidualFCN, rotate

SMALL = dict(widths=(4, 8, 8))


def make_policy(shape=(4, 13, 21), maps=(("pick", 0), ("push", 0), ("push", 180)), **kw) -> FCNPolicy:
    obs = gym.spaces.Box(0, 255, shape, dtype=np.uint8)
    act = gym.spaces.Discrete(len(maps) * shape[1] * shape[2])
    th.manual_seed(0)
    return FCNPolicy(obs, act, lambda _: 1e-3, maps=maps, **{**SMALL, **kw})


def random_obs(policy: FCNPolicy, n: int, seed: int = 0) -> th.Tensor:
    g = th.Generator().manual_seed(seed)
    return th.randint(0, 256, (n, *policy.observation_space.shape), generator=g, dtype=th.uint8)


def test_fcn_keeps_any_size():
    net = ResidualFCN(4, (4, 8, 8))
    for h, w in [(8, 16), (13, 21), (80, 120), (7, 9)]:
        assert net(th.rand(2, 4, h, w)).shape == (2, h, w)


def test_q_maps_shape_and_rotation():
    policy = make_policy()
    images = policy.images(random_obs(policy, 3))
    with th.no_grad():
        q = policy.q_net.q_maps(images)
        assert q.shape == (3, 3, 13, 21)
        push = policy.q_net.fcns["push"]
        assert th.allclose(q[:, 1], push(images), atol=1e-6)
        # 180° map = push FCN on the rotated image, its map rotated back (exact flips)
        assert th.allclose(q[:, 2], th.flip(push(th.flip(images, (-2, -1))), (-2, -1)), atol=1e-6)
        # equivariance: the 180° map of an image is the rotated 0° map of the rotated image
        q_rot = policy.q_net.q_maps(rotate(images, 180))
        assert th.allclose(q[:, 2], rotate(q_rot[:, 1], 180), atol=1e-5)


def test_q_values_at_matches_full_maps_in_batch_order():
    policy = make_policy()
    obs = random_obs(policy, 7)
    images = policy.images(obs)
    actions = th.tensor([0, 300, 273 * 2 + 5, 273 + 17, 272, 273 * 3 - 1, 273 * 2])
    with th.no_grad():
        full = policy.q_net.q_maps(images).flatten(1)
        picked = policy.q_values_at(policy.q_net, images, actions)
    assert th.allclose(picked, full[th.arange(7), actions], atol=1e-6)


def test_predict_is_argmax_over_all_maps():
    policy = make_policy()
    obs = random_obs(policy, 4)
    with th.no_grad():
        expected = policy.q_net.q_maps(policy.images(obs)).flatten(1).argmax(1)
    actions, _ = policy.predict(obs.numpy(), deterministic=True)
    assert np.array_equal(actions, expected.numpy())


def test_pick_only_layout_and_shared_push_weights():
    s_policy = make_policy(maps=(("pick", 0),))
    assert list(s_policy.q_net.fcns) == ["pick"]
    ps_policy = make_policy()
    assert list(ps_policy.q_net.fcns) == ["pick", "push"]


def test_layout_mismatch_names_both_sizes():
    obs = gym.spaces.Box(0, 255, (4, 10, 12), dtype=np.uint8)
    with pytest.raises(ValueError, match=r"Discrete\(120\).*3 maps x 10 x 12 pixels = 360"):
        FCNPolicy(obs, gym.spaces.Discrete(120), lambda _: 1e-3)


@pytest.mark.parametrize(
    "obs_space, act_space, message",
    [
        (gym.spaces.Box(0, 1, (10,), dtype=np.float32), gym.spaces.Discrete(10), "image observation"),
        (gym.spaces.Box(0, 255, (4, 10, 12), dtype=np.float32), gym.spaces.Discrete(360), "uint8"),
        (gym.spaces.Box(0, 255, (4, 10, 12), dtype=np.uint8), gym.spaces.MultiDiscrete([3, 10]), "Discrete"),
    ],
)
def test_bad_spaces_are_named(obs_space, act_space, message):
    with pytest.raises(ValueError, match=message):
        FCNPolicy(obs_space, act_space, lambda _: 1e-3)


def test_bad_map_layouts():
    with pytest.raises(ValueError, match="rotation must be one of"):
        make_policy(maps=(("pick", 0), ("push", 90), ("push", 180)))
    with pytest.raises(ValueError, match="twice"):
        make_policy(maps=(("pick", 0), ("pick", 0), ("push", 180)))


def test_wrong_observation_shape_is_an_error():
    model = PixelDoubleDQN("FCNPolicy", FindTheSquareEnv(), policy_kwargs=dict(maps=[("pick", 0)], **SMALL))
    with pytest.raises(ValueError, match="observation shape"):
        model.predict(np.zeros((4, 10, 10), dtype=np.uint8), deterministic=True)


def test_algorithm_rejects_mismatched_env():
    with pytest.raises(ValueError, match="does not match the Q-map layout"):
        PixelDoubleDQN("FCNPolicy", FindTheSquareEnv(n_maps=1), policy_kwargs=SMALL)
