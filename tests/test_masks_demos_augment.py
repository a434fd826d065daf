"""Issue 9 levers of PixelDoubleDQN on synthetic envs: one action mask everywhere, demonstrations with
the large-margin loss, augmentation hooks, hard target copies, no-op handling, the greedy gate."""

import copy

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from pixel_envs import CoinEnv, FindTheSquareEnv, SquareSupervisor
from stable_baselines3.common.logger import configure

from sb3_pixeldqn import CurriculumCallback, HindsightRelabelReplayBuffer, PixelDoubleDQN
from sb3_pixeldqn.pixel_dqn import get_action_masks

SMALL = dict(widths=(4, 8, 8))
MAPS3 = (("pick", 0), ("push", 0), ("push", 180))
HW = 12 * 20


def make_model(env=None, n_maps: int = 3, **kw) -> PixelDoubleDQN:
    env = env or FindTheSquareEnv(n_maps=n_maps, good_map=n_maps - 1)
    kw.setdefault("buffer_size", 500)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=MAPS3[:n_maps], **SMALL), seed=0, **kw)
    model.set_logger(configure(None, []))
    return model


def q_of(model: PixelDoubleDQN, obs: np.ndarray) -> th.Tensor:
    with th.no_grad():
        return model.q_net.q_maps(th.as_tensor(obs[None]).float() / 255).flatten(1)[0]


class SquarePolicy:
    """A demonstrator with SB3's predict: the centre of the square on the paying map."""

    def __init__(self, env: FindTheSquareEnv) -> None:
        self.env = env
        self.action_space = env.action_space

    def predict(self, obs, deterministic=True):
        obs = np.asarray(obs)
        batch = obs if obs.ndim == 4 else obs[None]
        actions = []
        for o in batch:
            rows, cols = np.nonzero(o[0] > 0)
            actions.append(self.env.good_map * HW + int(rows.mean()) * 20 + int(cols.mean()))
        return np.array(actions), None


# ---------------------------------------------------------------- masks
def test_predict_takes_the_argmax_over_allowed_actions_only():
    model = make_model()
    obs, _ = FindTheSquareEnv(n_maps=3).reset(seed=3)
    q = q_of(model, obs)
    best = int(q.argmax())
    mask = np.ones(3 * HW, dtype=bool)
    mask[best] = False
    mask[:HW] = False  # nothing on the pick map either
    action, _ = model.predict(obs, deterministic=True, action_masks=mask)
    allowed_q = q.clone()
    allowed_q[~th.as_tensor(mask)] = -th.inf
    assert int(action) == int(allowed_q.argmax()) and mask[int(action)]
    # no mask: the paper's argmax over every map and pixel, even though the env offers masks
    assert int(model.predict(obs, deterministic=True)[0]) == best
    # batched observations with batched masks
    actions, _ = model.predict(np.stack([obs, obs]), deterministic=True, action_masks=np.stack([mask, mask]))
    assert actions.tolist() == [int(action)] * 2
    # exploratory actions are drawn among allowed actions too
    model.exploration_rate = 1.0
    assert all(mask[int(model.predict(obs, deterministic=False, action_masks=mask)[0])] for _ in range(30))


def test_bad_masks_are_named():
    model = make_model()
    obs, _ = FindTheSquareEnv(n_maps=3).reset(seed=0)
    with pytest.raises(ValueError, match="expected \\(720,\\) per observation"):
        model.predict(obs, deterministic=True, action_masks=np.ones(100, dtype=bool))
    with pytest.raises(ValueError, match="must be a bool array.*int64"):
        model.predict(obs, deterministic=True, action_masks=np.ones(3 * HW, dtype=np.int64))
    with pytest.raises(ValueError, match="allows no action"):
        model.predict(obs, deterministic=True, action_masks=np.zeros(3 * HW, dtype=bool))


def test_greedy_collection_honours_the_env_mask():
    # an untrained net: unmasked greedy actions almost never land on the 9 square pixels; masked, always
    for masked, expect in ((True, True), (False, False)):
        model = make_model(learning_starts=0, exploration_initial_eps=0.0, exploration_final_eps=0.0, masked=masked)
        env = model.get_env()
        model._last_obs = env.reset()
        base = env.envs[0].unwrapped
        hits = []
        for _ in range(10):
            action = int(model._sample_action(0)[0][0])
            hits.append(bool(base.action_masks()[action]))
            model._last_obs = env.reset()
        assert all(hits) if expect else not all(hits)


def test_masked_requires_masks_and_any_env_with_action_masks_works():
    class Plain(gym.Env):
        observation_space = gym.spaces.Box(0, 255, (4, 12, 20), dtype=np.uint8)
        action_space = gym.spaces.Discrete(HW)

        def reset(self, *, seed=None, options=None):
            return np.zeros((4, 12, 20), dtype=np.uint8), {}

        def step(self, action):
            return np.zeros((4, 12, 20), dtype=np.uint8), -1.0, True, False, {}

    with pytest.raises(ValueError, match="masked=True but the env has no action_masks"):
        PixelDoubleDQN("FCNPolicy", Plain(), masked=True, policy_kwargs=dict(maps=[("pick", 0)], **SMALL))
    auto = PixelDoubleDQN("FCNPolicy", Plain(), policy_kwargs=dict(maps=[("pick", 0)], **SMALL))
    assert not auto._use_masks  # masked=None: only if the env offers them
    model = make_model()
    assert model._use_masks
    assert get_action_masks(model.get_env()).shape == (1, 3 * HW)
    square = FindTheSquareEnv(n_maps=3)
    square.reset(seed=0)
    gym_masks = get_action_masks(square)  # the Gymnasium-env path
    assert gym_masks.shape == (3 * HW,) and gym_masks.dtype == bool and np.array_equal(gym_masks, square.action_masks())


def test_target_argmax_uses_the_stored_next_mask():
    model = make_model()
    with th.no_grad():
        for p in model.q_net_target.parameters():
            p.add_(0.05 * th.randn_like(p))
    g = th.Generator().manual_seed(1)
    next_obs = th.randint(0, 256, (4, 4, 12, 20), generator=g, dtype=th.uint8)
    rewards, dones = th.full((4,), -1.0), th.zeros(4)
    images = next_obs.float() / 255
    with th.no_grad():
        online = model.q_net.q_maps(images).flatten(1)
        target = model.q_net_target.q_maps(images).flatten(1)
    masks = th.zeros(4, 3 * HW, dtype=th.bool)
    for i in range(4):  # allow 5 actions per row, none of them the unmasked argmax
        allowed = th.randperm(3 * HW, generator=g)[:5]
        allowed = allowed[allowed != online[i].argmax()]
        masks[i, allowed] = True
    y = model.double_dqn_target(next_obs, rewards, dones, masks)
    best = online.masked_fill(~masks, -th.inf).argmax(1)
    assert th.allclose(y, -1.0 + 0.9 * target[th.arange(4), best], atol=1e-6)
    assert not th.allclose(y, model.double_dqn_target(next_obs, rewards, dones))


def test_training_samples_use_masks_unless_masked_is_false(monkeypatch):
    seen = []
    for masked in (None, False):
        model = make_model(learning_starts=0, masked=masked)
        model.learn(6)
        original = model.double_dqn_target
        monkeypatch.setattr(model, "double_dqn_target",
                            lambda n, r, d, m=None, f=original: seen.append(m) or f(n, r, d, m))
        model.train(1, batch_size=4)
    assert seen[0] is not None and seen[0].dtype == th.bool and seen[1] is None


# ---------------------------------------------------------------- demonstrations
def test_strict_margin_loss_equals_the_hand_value():
    model = make_model(margin=0.1)
    q_all = th.tensor([[1.0, 0.95, 0.5, 0.93], [0.2, 0.9, 0.1, 0.15], [0.3, 0.1, 0.05, 0.0], [0.4, 0.6, 0.4, 0.4]],
                      requires_grad=True)
    actions = th.tensor([0, 0, 0, 3])
    # violators are the other actions within the margin of the demonstration (excess q + 0.1 - q_E > 0):
    # row 0: 0.05 and 0.03 -> 0.04; row 1: 0.8 and 0.05 (0.1 + 0.1 - 0.2 = 0 is not a violator) -> 0.425;
    # row 2: none -> 0; row 3 (demonstration = action 3): 0.1, 0.3, 0.1 -> 0.5/3
    expected = (0.04 + 0.425 + 0.0 + 0.5 / 3) / 4
    loss = model.margin_loss(q_all, actions)
    assert loss.item() == pytest.approx(expected, abs=1e-6)
    loss.backward()
    # every violator is pushed down (not just the largest), the demonstration up
    assert th.allclose(q_all.grad[0], th.tensor([-1.0, 0.5, 0.0, 0.5]) / 4)
    assert q_all.grad[2].abs().sum() == 0


def test_training_loss_is_huber_plus_weighted_margin_on_demonstration_rows():
    """`pixel_loss`, which `train` calls, adds ``margin_weight`` x the margin loss of demo rows only."""
    import torch.nn.functional as F

    model = make_model(margin=0.1, margin_weight=0.7)
    g = th.Generator().manual_seed(3)
    obs = th.randint(0, 256, (4, *model.observation_space.shape), generator=g, dtype=th.uint8)
    actions = th.randint(0, model.action_space.n, (4, 1), generator=g)
    targets = th.tensor([0.5, -1.0, 0.0, -0.2])
    demo = th.tensor([True, False, True, False])
    with th.no_grad():
        q_all = model.q_net.q_maps(model.policy.images(obs)).flatten(1)
        huber = F.smooth_l1_loss(q_all.gather(1, actions).squeeze(1), targets)
        margin = model.margin_loss(q_all[demo], actions[demo])
        total, part = model.pixel_loss(obs, actions, targets, demo)
        plain, none = model.pixel_loss(obs, actions, targets)
    assert margin.item() > 0  # the check below would be blind otherwise
    assert part.item() == pytest.approx(margin.item(), rel=1e-5)
    assert total.item() == pytest.approx(huber.item() + 0.7 * margin.item(), rel=1e-5)
    assert none is None and plain.item() == pytest.approx(huber.item(), rel=1e-5)


def test_demonstrations_are_kept_flagged_and_trained_with_the_margin():
    env = FindTheSquareEnv(n_maps=3, good_map=2)
    model = make_model(env, learning_starts=0, demo_fraction=0.5, buffer_size=20)
    stats = model.collect_demonstrations(SquarePolicy(env), 12)
    demos = model.replay_buffer.demonstrations
    assert stats == {"episodes": 12, "successes": 12, "steps": 12, "counterfactuals": 0} and demos.n_stored == 12
    assert model.num_timesteps == 0 and model.demo_timesteps == 12
    model.learn(40)  # the ring (20 slots) wraps twice; the demonstrations stay
    assert model.replay_buffer.full and model.replay_buffer.demonstrations.n_stored == 12
    batch = model.replay_buffer.sample_arrays(16, 0.5)
    assert batch.is_demo.sum() == 8 and (batch.rewards[batch.is_demo] == 0.0).all()
    # the margin loss runs on demonstration rows (logged) and moves Q towards the demonstrated pixel
    before = copy.deepcopy(model.q_net.state_dict())
    model.train(3, batch_size=16)
    assert model.logger.name_to_value["train/margin_loss"] >= 0
    assert any(not th.equal(before[k], v) for k, v in model.q_net.state_dict().items())


class ProbingSquarePolicy(SquarePolicy):
    """SquarePolicy that reports, after each predict, one rejected action (the same pixel on the pick
    map) as ending the episode with reward -10, as a teacher that probes a copy of the env would."""

    def __init__(self, env: FindTheSquareEnv, report=None) -> None:
        super().__init__(env)
        self.report = report
        self.last = None

    def predict(self, obs, deterministic=True):
        actions, state = super().predict(obs, deterministic)
        self.last = np.asarray(obs).reshape(-1, *self.env.observation_space.shape)[0]
        return actions, state

    def counterfactuals(self):
        if self.report is not None:
            return self.report(self.last)
        action = int(self.env.good_map * HW + np.argmax(self.last[0].reshape(-1) > 0))
        return [(action - self.env.good_map * HW, -10.0, np.zeros_like(self.last))]


def test_counterfactuals_are_kept_as_terminal_transitions_of_the_same_state_without_the_margin():
    env = FindTheSquareEnv(n_maps=3, good_map=2)
    model = make_model(env, learning_starts=0, demo_fraction=0.5, buffer_size=20)
    stats = model.collect_demonstrations(ProbingSquarePolicy(env), 5, counterfactuals=True)
    assert stats == {"episodes": 5, "successes": 5, "steps": 5, "counterfactuals": 5}
    assert model.demo_timesteps == 5 and model.num_timesteps == 0  # counterfactuals are not env steps
    demos = model.replay_buffer.demonstrations
    assert demos.n_stored == 10 and demos.expert[:10].tolist() == [False, True] * 5  # each before its step
    rejected, shown = np.arange(0, 10, 2), np.arange(1, 10, 2)
    assert np.array_equal(demos.observations[rejected], demos.observations[shown])  # the same state
    assert (demos.actions[rejected, 0, 0] < HW).all() and (demos.actions[shown, 0, 0] >= 2 * HW).all()
    assert (demos.rewards[rejected, 0] == -10.0).all() and (demos.dones[rejected, 0] == 1.0).all()
    batch = model.replay_buffer.sample_arrays(32, 1.0, np.random.default_rng(0))
    assert (batch.is_demo == (batch.actions >= 2 * HW)).all()  # margin rows: the demonstrated actions only
    # without the option nothing else is stored, and a demonstrator without the method is refused
    plain = make_model(env, learning_starts=0, demo_fraction=0.5)
    assert plain.collect_demonstrations(ProbingSquarePolicy(env), 3)["counterfactuals"] == 0
    assert plain.replay_buffer.demonstrations.n_stored == 3
    with pytest.raises(ValueError, match="needs a demonstrator with a counterfactuals\\(\\) method.*SquarePolicy"):
        plain.collect_demonstrations(SquarePolicy(env), 3, counterfactuals=True)
    for report in (lambda o: [(10**6, -10.0, o)], lambda o: [(0, -10.0, o[0])], lambda o: [(0.5, -10.0, o)]):
        with pytest.raises(ValueError, match="reported a counterfactual with action .* expected an action in "
                                             "\\[0, 720\\) and shape \\(4, 12, 20\\)"):
            plain.collect_demonstrations(ProbingSquarePolicy(env, report), 2, counterfactuals=True)


def test_demonstration_policy_on_the_wrong_layout_is_refused():
    model = make_model()
    wrong = SquarePolicy(FindTheSquareEnv(n_maps=1))
    with pytest.raises(ValueError, match="acts in Discrete\\(240\\).*Discrete\\(720\\)"):
        model.collect_demonstrations(wrong, 3)

    class OutOfRange(SquarePolicy):
        action_space = None

        def predict(self, obs, deterministic=True):
            return np.array([10**6]), None

    with pytest.raises(ValueError, match="expected 1 action\\(s\\) in \\[0, 720\\)"):
        model.collect_demonstrations(OutOfRange(FindTheSquareEnv(n_maps=3)), 3)


def test_demonstrations_round_trip_through_save_replay_buffer(tmp_path):
    env = FindTheSquareEnv(n_maps=3, good_map=2)
    model = make_model(env)
    model.collect_demonstrations(SquarePolicy(env), 5)
    model.save_replay_buffer(tmp_path / "replay")
    other = make_model()
    other.load_replay_buffer(tmp_path / "replay.pkl")
    a, b = model.replay_buffer.demonstrations, other.replay_buffer.demonstrations
    assert b.n_stored == a.n_stored == 5
    for name in ("observations", "actions", "rewards", "next_masks"):
        assert np.array_equal(getattr(a, name)[:5], getattr(b, name)[:5]), name


# ---------------------------------------------------------------- augmentation
def test_augmentation_transforms_every_sampled_transition_and_checks_layouts():
    def flip_cols(obs, action, next_obs, mask, rng):
        m, rest = divmod(action, HW)
        r, c = divmod(rest, 20)
        flipped = mask.reshape(3, 12, 20)[..., ::-1].reshape(-1)
        return obs[..., ::-1].copy(), m * HW + r * 20 + 19 - c, next_obs[..., ::-1].copy(), flipped

    model = make_model(learning_starts=0, augment=[flip_cols])
    model.learn(8)
    batch = model.replay_buffer.sample_arrays(4, 0.0, np.random.default_rng(0))
    out = model.augmented(batch)
    assert np.array_equal(out.observations, batch.observations[..., ::-1])
    assert ((out.actions % 20) == 19 - (batch.actions % 20)).all()
    model.train(1, batch_size=4)  # runs through train()

    def crop(obs, action, next_obs, mask, rng):
        return obs[:, :-1], action, next_obs, mask

    bad = make_model(learning_starts=100, augment=[crop])
    bad.learn(4)
    with pytest.raises(ValueError, match="augmentation .*crop.* changed a transition's layout"):
        bad.train(1, batch_size=2)
    with pytest.raises(ValueError, match="augment must hold callables"):
        make_model(augment=["mirror"])


# ---------------------------------------------------------------- target, no-ops
def test_hard_target_copies_every_interval():
    model = make_model(learning_starts=0, tau=1.0, target_update_interval=3)
    model.learn(10)
    model._n_updates = 0
    start = copy.deepcopy(model.q_net_target.state_dict())
    model.train(2, batch_size=4)
    for k, v in model.q_net_target.state_dict().items():
        assert th.equal(v, start[k]), k  # not yet
    model.train(1, batch_size=4)
    for k, v in model.q_net_target.state_dict().items():
        assert th.equal(v, model.q_net.state_dict()[k]), k  # copied at the 3rd update


def test_noop_modes_and_relabelling_only_changed_steps():
    space = gym.spaces.Box(0, 255, (4, 6, 8), dtype=np.uint8)
    same = np.full((1, 4, 6, 8), 7, dtype=np.uint8)
    other = np.full((1, 4, 6, 8), 9, dtype=np.uint8)
    twin = {"relabelled": {"obs": same[0], "next_obs": same[0], "reward": 0.0, "terminated": True}}
    results = {}
    for noop in ("keep", "penalty", "terminal"):
        buf = HindsightRelabelReplayBuffer(8, space, gym.spaces.Discrete(48), device="cpu", noop=noop,
                                           noop_penalty=2.0)
        buf.add(same, same, np.array([1]), np.array([-1.0]), np.array([0.0]), [dict(twin)])
        buf.add(same, other, np.array([1]), np.array([-1.0]), np.array([0.0]), [{}])
        results[noop] = (float(buf.rewards[0, 0]), float(buf.dones[0, 0]), float(buf.rewards[1, 0]), buf.pos,
                         buf.n_noop)
    assert results["keep"] == (-1.0, 0.0, -1.0, 2, 1)  # the no-op's relabelled twin is not stored
    assert results["penalty"] == (-3.0, 0.0, -1.0, 2, 1)
    assert results["terminal"] == (-3.0, 1.0, -1.0, 2, 1)
    every = HindsightRelabelReplayBuffer(8, space, gym.spaces.Discrete(48), device="cpu", relabel="all")
    every.add(same, same, np.array([1]), np.array([-1.0]), np.array([0.0]), [dict(twin)])
    assert every.pos == 2 and every.n_relabelled == 1
    off = HindsightRelabelReplayBuffer(8, space, gym.spaces.Discrete(48), device="cpu", relabel="off")
    off.add(same, other, np.array([1]), np.array([-1.0]), np.array([0.0]), [dict(twin)])
    assert off.pos == 1
    with pytest.raises(ValueError, match="noop must be one of"):
        HindsightRelabelReplayBuffer(8, space, gym.spaces.Discrete(48), device="cpu", noop="skip")


# ---------------------------------------------------------------- greedy gate
def test_greedy_gate_promotes_on_the_deterministic_policy_only():
    for p_success, expect in ((1.0, 2), (0.0, 1)):
        model = make_model(CoinEnv(p_success=p_success), n_maps=1, learning_starts=10**6)
        gate = CurriculumCallback(start_value=1, max_value=3, gate="greedy", eval_env=CoinEnv(p_success=p_success),
                                  eval_every=5, eval_episodes=4)
        model.learn(9, callback=gate)
        assert gate.value == expect
        assert [h[1:] for h in gate.greedy_history] == [[1, p_success]]
        assert model.curriculum_state["greedy_history"] == gate.greedy_history
    with pytest.raises(ValueError, match="needs an eval_env"):
        CurriculumCallback(gate="greedy")


def test_greedy_checks_act_as_the_model_was_trained(monkeypatch):
    # a model trained with masked=False keeps its all-pixel argmax in the curriculum's greedy checks
    for masked, expect_masks in ((None, True), (False, False)):
        model = make_model(CoinEnv(p_success=1.0), n_maps=1, learning_starts=10**6, masked=masked)
        seen: list = []

        def spy(obs, seen=seen, original=model.predict, **kw):
            seen.append(kw.get("action_masks"))
            return original(obs, **kw)

        monkeypatch.setattr(model, "predict", spy)
        gate = CurriculumCallback(gate="greedy", eval_env=CoinEnv(p_success=1.0), eval_every=3, eval_episodes=2)
        model.learn(4, callback=gate)
        assert seen and all((m is not None) == expect_masks for m in seen)


def test_corrections_store_the_executed_action_and_keep_both_halves_of_the_correction():
    sup = SquareSupervisor(FindTheSquareEnv(n_maps=3, good_map=2, relabel=True))
    model = make_model(sup, learning_starts=10**6, buffer_size=200)  # every action exploratory, no training
    model.learn(30)
    ring, demos = model.replay_buffer, model.replay_buffer.demonstrations
    assert 10 <= sup.corrections == model.n_corrections < 30  # a masked draw hits map 2 a third of the time
    assert model.logger.name_to_value["rollout/corrections"] == model.n_corrections
    # the ring holds what happened: every episode succeeded with the executed action, on the paying map
    assert ring.n_stored == 30 and (ring.actions[:30, 0, 0] >= 2 * HW).all() and (ring.rewards[:30, 0] == 0).all()
    # kept: per correction the vetoed action (terminal, -10, TD only) then the executed transition
    n = model.n_corrections
    assert demos.n_stored == 2 * n and demos.expert[:2 * n].tolist() == [False, True] * n
    vetoed, shown = np.arange(0, 2 * n, 2), np.arange(1, 2 * n, 2)
    assert np.array_equal(demos.observations[vetoed], demos.observations[shown])  # the same state
    assert (demos.actions[vetoed, 0, 0] < 2 * HW).all() and (demos.actions[shown, 0, 0] >= 2 * HW).all()
    assert (demos.rewards[vetoed, 0] == -10).all() and (demos.dones[vetoed, 0] == 1).all()
    assert (demos.next_observations[vetoed] == 0).all() and (demos.rewards[shown, 0] == 0).all()
    # the executed transition succeeded, so it has no relabelled twin (the env relabels failures only)
    batch = model.replay_buffer.sample_arrays(32, 1.0, np.random.default_rng(0))
    assert (batch.is_demo == (batch.actions >= 2 * HW)).all()
    # a report that does not fit the model is named
    bad_reports = (lambda r: {**r, "executed": 10**6}, lambda r: {**r, "next_obs": r["next_obs"][0]},
                   lambda r: {k: v for k, v in r.items() if k != "reward"})
    for bad in bad_reports:
        model = make_model(SquareSupervisor(FindTheSquareEnv(n_maps=3, good_map=2), bad), learning_starts=10**6)
        with pytest.raises(ValueError, match='info\\["correction"\\]'):
            model.learn(10)
