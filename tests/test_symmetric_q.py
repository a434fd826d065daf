"""research/symmetric_q.py: the Q-maps averaged over the cabinet's 12 symmetries are exactly equivariant
(a mirrored scene's mean map is the mirrored mean map; renamed classes change nothing), where the
network alone is not; acting is the masked argmax of that mean; evaluations play ``<zip>+symmetric``."""

import gymnasium as gym
import numpy as np
import pytest

from research.symmetric_q import SYMMETRIC, SymmetricQ
from sb3_pixeldqn import PixelDoubleDQN
from shelf_env import policies
from shelf_env.actions import ActionCodec
from shelf_env.symmetry import MirrorWidth, PermuteClasses


@pytest.fixture(scope="module")
def scene():
    env = gym.make("ShelfSort-v0", num_objects=4, pixel_size=0.02)
    obs, _ = env.reset(seed=3)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(widths=(4, 8, 8)), seed=0)
    masks = env.unwrapped.action_masks()
    yield env, model, obs, masks
    env.close()


def test_the_mean_is_equivariant_where_the_network_is_not(scene):
    env, model, obs, _ = scene
    mirror = MirrorWidth.for_env(env, p=1.0)
    sym = SymmetricQ.for_env(model, env)
    assert sym.n_views == 12
    q = sym.q_maps(obs)
    assert q.shape == (len(ActionCodec.of(env).map_names), *obs.shape[1:])
    mirrored = sym.q_maps(mirror.observation(obs))
    assert np.allclose(mirror.mask(mirrored.reshape(-1)), q.reshape(-1), atol=1e-5)
    for perm in ([1, 0, 2], [2, 0, 1]):
        assert np.allclose(sym.q_maps(PermuteClasses().observation(obs, perm)), q, atol=1e-5)
    # the network alone: its mirrored scene's map is not the mirrored map, nor its renamed scene's the same
    plain = model.policy.q_map_values(obs)
    assert not np.allclose(mirror.mask(model.policy.q_map_values(mirror.observation(obs)).reshape(-1)),
                           plain.reshape(-1), atol=1e-3)
    assert not np.allclose(model.policy.q_map_values(PermuteClasses().observation(obs, [1, 0, 2])), plain, atol=1e-3)
    # with neither symmetry it is the network itself
    alone = SymmetricQ.for_env(model, env, mirror=False, permutations=False)
    assert alone.n_views == 1 and np.allclose(alone.q_maps(obs), plain, atol=1e-6)


def test_acting_is_the_masked_argmax_of_the_mean(scene):
    env, model, obs, masks = scene
    sym = SymmetricQ.for_env(model, env)
    q = sym.q_maps(obs).reshape(-1)
    action, state = sym.predict(obs, deterministic=True, action_masks=masks)
    assert state is None and masks[action] and q[action] == q[masks].max()
    assert int(sym.predict(obs)[0]) == int(q.argmax())
    batch, _ = sym.predict(np.stack([obs, obs]), action_masks=np.stack([masks, masks]))
    assert batch.tolist() == [action, action]
    # the mirrored scene's choice is the mirror of the scene's (ties aside: the means are continuous)
    mirror = MirrorWidth.for_env(env, p=1.0)
    mirrored, _ = sym.predict(mirror.observation(obs), action_masks=mirror.mask(masks))
    assert mirror.action(int(mirrored)) == int(action)


def test_bad_input_and_the_evaluation_name(scene, tmp_path):
    env, model, obs, masks = scene
    sym = SymmetricQ.for_env(model, env)
    with pytest.raises(ValueError, match="action_masks"):
        sym.predict(obs, action_masks=masks[:-1])
    with pytest.raises(ValueError, match="no policy.q_map_values"):
        SymmetricQ(object(), ActionCodec.of(env))
    with pytest.raises(ValueError, match="maps of"):
        SymmetricQ(model, ActionCodec(("pick",), 4, 6, 0.01))
    model.save(tmp_path / "p.zip")
    name = str(tmp_path / "p.zip") + SYMMETRIC
    assert policies.policy_label(name) == "p+symmetric"
    agent = policies.make_policy(name, env)
    assert isinstance(agent, SymmetricQ) and agent.acts_masked and agent.n_views == 12
    assert int(agent.predict(obs, action_masks=masks)[0]) == int(sym.predict(obs, action_masks=masks)[0])
