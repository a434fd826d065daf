"""PixelDoubleDQN maths and persistence, in the style of sb3-contrib's tests."""

import copy
import zipfile

import numpy as np
import pytest
import torch as th
from pixel_envs import FindTheSquareEnv
from stable_baselines3.common.logger import configure

from sb3_pixeldqn import PICK_ONLY_MAPS, PixelDoubleDQN

SMALL = dict(widths=(4, 8, 8))


def make_model(n_maps: int = 3, **kw) -> PixelDoubleDQN:
    maps = (("pick", 0), ("push", 0), ("push", 180))[:n_maps]
    env = FindTheSquareEnv(n_maps=n_maps, good_map=n_maps - 1)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=maps, **SMALL), seed=0, buffer_size=500, **kw)
    model.set_logger(configure(None, []))
    return model


def batch(model: PixelDoubleDQN, n: int = 6, seed: int = 0):
    g = th.Generator().manual_seed(seed)
    shape = model.observation_space.shape
    obs = th.randint(0, 256, (n, *shape), generator=g, dtype=th.uint8)
    next_obs = th.randint(0, 256, (n, *shape), generator=g, dtype=th.uint8)
    actions = th.randint(0, model.action_space.n, (n, 1), generator=g)
    return obs, next_obs, actions


def set_constant_output(net, value: float) -> None:
    """Make every FCN of ``net`` output ``value`` at every pixel (zero head weights, bias = value)."""
    with th.no_grad():
        for fcn in net.fcns.values():
            fcn.head.weight.zero_()
            fcn.head.bias.fill_(value)


def huber(delta: np.ndarray) -> np.ndarray:
    a = np.abs(delta)
    return np.where(a < 1, 0.5 * delta**2, a - 0.5)


def test_loss_equals_hand_computed_huber():
    model = make_model()
    set_constant_output(model.q_net, 0.25)
    obs, _, actions = batch(model, 4)
    targets = th.tensor([0.0, -0.5, 3.25, -2.0])
    loss, _ = model.pixel_loss(obs, actions, targets)
    expected = huber(0.25 - targets.numpy()).mean()  # 0.03125, 0.28125, 2.5, 1.75
    assert loss.item() == pytest.approx(expected, abs=1e-6)


def test_double_dqn_target_equals_hand_computation():
    model = make_model()
    with th.no_grad():  # make the target net differ from the online net
        for p in model.q_net_target.parameters():
            p.add_(0.05 * th.randn_like(p))
    _, next_obs, _ = batch(model, 5)
    rewards = th.tensor([[-1.0], [0.0], [-1.0], [-10.0], [-1.0]])
    dones = th.tensor([[0.0], [1.0], [0.0], [1.0], [0.0]])
    y = model.double_dqn_target(next_obs, rewards, dones)

    images = next_obs.float() / 255
    with th.no_grad():
        online = model.q_net.q_maps(images).flatten(1)
        target = model.q_net_target.q_maps(images).flatten(1)
    best = online.argmax(1)
    expected = rewards[:, 0] + (1 - dones[:, 0]) * 0.9 * target[th.arange(5), best]
    assert th.allclose(y, expected, atol=1e-6)
    # terminal transitions bootstrap nothing
    assert y[1].item() == 0.0 and y[3].item() == -10.0
    # it is double DQN: not the target net's own max
    assert not th.allclose(y, rewards[:, 0] + (1 - dones[:, 0]) * 0.9 * target.max(1).values)


def test_gradient_only_through_executed_pixel_and_network():
    model = make_model()
    obs, _, _ = batch(model, 3)
    hw = 12 * 20
    actions = th.tensor([[5], [hw + 7], [hw + 100]])  # one pick, two push-left; nothing on push-right
    captured = []

    def keep_grad(module, inputs, output):
        output.register_hook(lambda g: captured.append((module, g.clone())))

    handles = [fcn.register_forward_hook(keep_grad) for fcn in model.q_net.fcns.values()]
    model.policy.optimizer.zero_grad()
    model.pixel_loss(obs, actions, th.tensor([1.0, -1.0, 2.0]))[0].backward()
    for h in handles:
        h.remove()

    grads = {id(m): g for m, g in captured}
    pick_grad = grads[id(model.q_net.fcns["pick"])]
    push_grad = grads[id(model.q_net.fcns["push"])]
    assert pick_grad.shape == (1, 12, 20) and push_grad.shape == (2, 12, 20)  # only executed maps ran
    assert th.count_nonzero(pick_grad) == 1 and pick_grad[0, 0, 5] != 0
    assert th.count_nonzero(push_grad) == 2 and push_grad[0, 0, 7] != 0 and push_grad[1, 100 // 20, 100 % 20] != 0

    # an executed action only on the pick map gives the push network exactly zero gradient
    model.policy.optimizer.zero_grad()
    model.pixel_loss(obs[:1], actions[:1], th.tensor([1.0]))[0].backward()
    for p in model.q_net.fcns["push"].parameters():
        assert p.grad is None or th.count_nonzero(p.grad) == 0
    assert any(th.count_nonzero(p.grad) > 0 for p in model.q_net.fcns["pick"].parameters())
    for p in model.q_net_target.parameters():
        assert p.grad is None


def test_polyak_update_after_each_gradient_step():
    model = make_model(tau=0.1)
    env = model.get_env()
    obs = env.reset()
    for _ in range(40):
        action = np.array([env.action_space.sample()])
        next_obs, reward, done, infos = env.step(action)
        model.replay_buffer.add(obs, next_obs, action, reward, done, infos)
        obs = next_obs
    target_before = copy.deepcopy(model.q_net_target.state_dict())
    online_before = copy.deepcopy(model.q_net.state_dict())
    model.train(gradient_steps=1, batch_size=8)
    online_after = model.q_net.state_dict()
    for name, target_after in model.q_net_target.state_dict().items():
        expected = 0.9 * target_before[name] + 0.1 * online_after[name]
        assert th.allclose(target_after, expected, atol=1e-6), name
        assert not th.equal(online_after[name], online_before[name]) or "bias" in name


def test_epsilon_schedule_per_stage():
    model = make_model(exploration_initial_eps=0.8, exploration_final_eps=0.01, exploration_timesteps=100)
    assert model.exploration_rate == pytest.approx(0.8)
    model.stage_timesteps = 49
    model._on_step()
    assert model.exploration_rate == pytest.approx(0.8 - 0.5 * 0.79)
    model.stage_timesteps = 1000
    model._on_step()
    assert model.exploration_rate == pytest.approx(0.01)
    model.restart_exploration()
    assert model.exploration_rate == pytest.approx(0.8) and model.stage_timesteps == 0


def test_masked_exploration_draws_only_allowed_actions():
    model = make_model(n_maps=3, learning_starts=10**6)
    model._last_obs = model.get_env().reset()
    env = model.get_env().envs[0].unwrapped
    allowed = env.action_masks()
    picked = [int(model._sample_action(10**6)[0][0]) for _ in range(60)]
    assert all(allowed[a] for a in picked)
    assert len({a // (12 * 20) for a in picked}) == 3  # a map uniformly, then an allowed pixel


def test_save_load_keeps_parameters_actions_and_stage(tmp_path):
    model = make_model(learning_starts=5, exploration_timesteps=50)
    model.learn(30)
    model.curriculum_state = {"value": 3, "outcomes": [True, False], "history": [[0, 1], [20, 3]]}
    model.save(tmp_path / "model")
    assert (tmp_path / "model.zip").exists() and not list(tmp_path.glob(".*partial"))
    loaded = PixelDoubleDQN.load(tmp_path / "model.zip", env=FindTheSquareEnv(n_maps=3, good_map=2))
    for (name, a), (_, b) in zip(model.policy.state_dict().items(), loaded.policy.state_dict().items()):
        assert th.equal(a, b), name
    obs = np.stack([FindTheSquareEnv(n_maps=3).reset(seed=s)[0] for s in range(8)])
    assert np.array_equal(model.predict(obs, deterministic=True)[0], loaded.predict(obs, deterministic=True)[0])
    assert loaded.curriculum_state == model.curriculum_state
    assert loaded.stage_timesteps == model.stage_timesteps == 30
    assert loaded.exploration_rate == pytest.approx(model.exploration_rate)
    assert loaded.policy.maps == model.policy.maps
    assert loaded.policy.optimizer.state_dict()["param_groups"][0]["weight_decay"] == 2e-5


def test_load_errors_name_the_problem(tmp_path):
    model = make_model(n_maps=1)
    model.save(tmp_path / "s_model.zip")
    with pytest.raises(ValueError, match=r"does not fit this env.*\[pick@0\]"):
        PixelDoubleDQN.load(tmp_path / "s_model.zip", env=FindTheSquareEnv(n_maps=3))
    with pytest.raises(FileNotFoundError, match="no PixelDoubleDQN checkpoint at"):
        PixelDoubleDQN.load(tmp_path / "missing.zip")
    (tmp_path / "junk.zip").write_bytes(b"this is not a zip file")
    with pytest.raises(ValueError, match="not a readable PixelDoubleDQN checkpoint"):
        PixelDoubleDQN.load(tmp_path / "junk.zip")
    data = (tmp_path / "s_model.zip").read_bytes()
    (tmp_path / "cut.zip").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="not a readable PixelDoubleDQN checkpoint"):
        PixelDoubleDQN.load(tmp_path / "cut.zip")
    with zipfile.ZipFile(tmp_path / "s_model.zip") as src, zipfile.ZipFile(tmp_path / "nopolicy.zip", "w") as dst:
        for item in src.infolist():
            if item.filename != "policy.pth":
                dst.writestr(item, src.read(item.filename))
    with pytest.raises(ValueError, match="not a readable PixelDoubleDQN checkpoint"):
        PixelDoubleDQN.load(tmp_path / "nopolicy.zip")


def test_pick_only_variant_s():
    model = make_model(n_maps=1)
    assert model.policy.maps == PICK_ONLY_MAPS
    assert model.action_space.n == 12 * 20


def test_set_env_takes_another_number_of_envs_and_keeps_training():
    # parallel envs (shelf-train --n-envs): a model made on one env moves to three and back; every
    # env's step is stored, ε's stage clock counts env steps, and the replay ratio is what
    # gradient_steps says
    from stable_baselines3.common.vec_env import DummyVecEnv

    model = make_model(learning_starts=2, gradient_steps=3)
    model.set_env(DummyVecEnv([lambda: FindTheSquareEnv(n_maps=3, good_map=2)] * 3))
    assert model.n_envs == 3 and model.replay_buffer.n_source_envs == 3
    model.learn(12)
    assert model.num_timesteps == 12 and model.stage_timesteps == 12
    assert model.replay_buffer.size() == 12  # no relabelled twins in this env
    # 4 collection steps of the 3 envs, each past learning_starts, each followed by 3 gradient steps
    assert model._n_updates == 4 * 3
    model.set_env(FindTheSquareEnv(n_maps=3, good_map=2))
    assert model.n_envs == 1
    model.learn(2, reset_num_timesteps=False)
    assert model.num_timesteps == 14 and model.replay_buffer.size() == 14
    with pytest.raises(ValueError, match="Observation spaces do not match"):
        model.set_env(FindTheSquareEnv(shape=(4, 10, 20), n_maps=3))
