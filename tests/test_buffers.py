"""HindsightRelabelReplayBuffer: relabelled twins, flat multi-env storage, timeouts, persistence, memory."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
from pixel_envs import FindTheSquareEnv
from stable_baselines3.common.env_util import make_vec_env

from sb3_pixeldqn import HindsightRelabelReplayBuffer, PixelDoubleDQN

SHAPE = (4, 6, 8)
OBS_SPACE = gym.spaces.Box(0, 255, SHAPE, dtype=np.uint8)
ACT_SPACE = gym.spaces.Discrete(6 * 8)


def obs(value: int, n: int = 1) -> np.ndarray:
    return np.full((n, *SHAPE), value, dtype=np.uint8)


def relabelled(a: int, b: int) -> dict:
    return {"obs": obs(a)[0], "next_obs": obs(b)[0], "reward": 0.0, "terminated": True}


def test_relabelled_transition_is_stored_beside_the_original():
    buf = HindsightRelabelReplayBuffer(10, OBS_SPACE, ACT_SPACE, device="cpu")
    buf.add(obs(1), obs(2), np.array([7]), np.array([-1.0]), np.array([0.0]), [{"relabelled": relabelled(11, 12)}])
    buf.add(obs(3), obs(4), np.array([9]), np.array([-1.0]), np.array([0.0]), [{}])
    assert buf.pos == 3 and buf.n_relabelled == 1
    assert buf.observations[0, 0, 0, 0, 0] == 1 and buf.next_observations[0, 0, 0, 0, 0] == 2
    assert buf.observations[1, 0, 0, 0, 0] == 11 and buf.next_observations[1, 0, 0, 0, 0] == 12
    assert buf.actions[1, 0, 0] == 7  # the executed action is kept
    assert buf.rewards[1, 0] == 0.0 and buf.dones[1, 0] == 1.0
    assert buf.rewards[0, 0] == -1.0 and buf.dones[0, 0] == 0.0
    assert buf.observations[2, 0, 0, 0, 0] == 3


def test_flat_storage_for_several_envs_and_one_relabel():
    buf = HindsightRelabelReplayBuffer(12, OBS_SPACE, ACT_SPACE, device="cpu", n_envs=2)
    infos = [{}, {"relabelled": relabelled(50, 51)}]
    buf.add(np.concatenate([obs(1), obs(2)]), np.concatenate([obs(3), obs(4)]), np.array([1, 2]),
            np.array([-1.0, -1.0]), np.array([0.0, 0.0]), infos)
    assert buf.buffer_size == 12 and buf.pos == 3
    assert [int(buf.observations[i, 0, 0, 0, 0]) for i in range(3)] == [1, 2, 50]
    assert [int(buf.actions[i, 0, 0]) for i in range(3)] == [1, 2, 2]


def test_truncation_is_not_terminal_in_samples():
    buf = HindsightRelabelReplayBuffer(4, OBS_SPACE, ACT_SPACE, device="cpu")
    buf.add(obs(1), obs(2), np.array([0]), np.array([-1.0]), np.array([1.0]), [{"TimeLimit.truncated": True}])
    assert buf.sample(8).dones.max().item() == 0.0
    buf2 = HindsightRelabelReplayBuffer(4, OBS_SPACE, ACT_SPACE, device="cpu")
    buf2.add(obs(1), obs(2), np.array([0]), np.array([0.0]), np.array([1.0]), [{}])
    assert buf2.sample(8).dones.min().item() == 1.0


def test_bad_relabel_entries_are_named():
    buf = HindsightRelabelReplayBuffer(4, OBS_SPACE, ACT_SPACE, device="cpu")
    with pytest.raises(ValueError, match="keys obs, next_obs, reward, terminated"):
        buf.add(obs(1), obs(2), np.array([0]), np.array([-1.0]), np.array([0.0]), [{"relabelled": {"obs": 1}}])
    bad = relabelled(1, 2)
    bad["obs"] = np.zeros((3, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match=r"shape \(3, 3\)"):
        buf.add(obs(1), obs(2), np.array([0]), np.array([-1.0]), np.array([0.0]), [{"relabelled": bad}])
    with pytest.raises(ValueError, match="optimize_memory_usage"):
        HindsightRelabelReplayBuffer(4, OBS_SPACE, ACT_SPACE, optimize_memory_usage=True)


def test_pickle_keeps_only_the_filled_part_and_round_trips():
    buf = HindsightRelabelReplayBuffer(1000, OBS_SPACE, ACT_SPACE, device="cpu")
    for i in range(5):
        infos = [{"relabelled": relabelled(i, i)}]
        buf.add(obs(i), obs(i + 1), np.array([i]), np.array([-1.0]), np.array([0.0]), infos)
    blob = pickle.dumps(buf)
    assert len(blob) < 20 * 2 * np.prod(SHAPE) + 20_000  # 10 transitions, not 1000
    back = pickle.loads(blob)
    assert back.buffer_size == 1000 and back.pos == 10 and not back.full
    for name in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts"):
        assert np.array_equal(getattr(back, name), getattr(buf, name)), name


def test_save_and_load_replay_buffer_through_the_algorithm(tmp_path):
    env = make_vec_env(lambda: FindTheSquareEnv(relabel=True), n_envs=2)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)),
                           learning_starts=100, buffer_size=200, seed=0, replay_buffer_kwargs=dict(relabel="all"),
                           masked_exploration=False)
    model.learn(20)
    buf = model.replay_buffer
    assert buf.n_relabelled > 0 and buf.pos == 20 + buf.n_relabelled
    # next-state masks were stored (the env offers action_masks): the 9 square pixels, or all 240
    # actions at an episode's end, where this env gives no info["action_mask"]; twins included
    stored = np.unpackbits(buf.next_masks[: buf.pos], axis=1, count=12 * 20).astype(bool).sum(axis=1)
    assert set(stored) == {9, 240}
    model.save_replay_buffer(tmp_path / "replay")
    assert (tmp_path / "replay.pkl").exists() and not list(tmp_path.glob(".*partial"))
    other = PixelDoubleDQN("FCNPolicy", FindTheSquareEnv(), policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)))
    other.load_replay_buffer(tmp_path / "replay.pkl")
    for name in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts", "next_masks"):
        assert np.array_equal(getattr(other.replay_buffer, name), getattr(buf, name)), name
    assert other.replay_buffer.pos == buf.pos
    # the env is never part of what is pickled
    assert b"FindTheSquareEnv" not in (tmp_path / "replay.pkl").read_bytes()


def test_fifty_thousand_shelf_transitions_with_masks_fit_in_4_1_gb():
    space = gym.spaces.Box(0, 255, (4, 80, 120), dtype=np.uint8)
    buf = HindsightRelabelReplayBuffer(50_000, space, gym.spaces.Discrete(3 * 80 * 120), device="cpu")
    total = sum(getattr(buf, n).nbytes for n in ("observations", "next_observations", "actions", "rewards",
                                                   "dones", "timeouts", "next_masks"))
    assert buf.next_masks.nbytes == 50_000 * 3 * 80 * 120 // 8  # one bit per action
    assert total <= 4.1e9


def test_kept_transitions_carry_their_expert_flag_through_sampling_and_pickling():
    # add_demonstration(expert=False): kept and drawn like a demonstration, not flagged for the margin
    buf = HindsightRelabelReplayBuffer(8, OBS_SPACE, ACT_SPACE, device="cpu")
    for i in range(3):
        buf.add_demonstration(obs(i), obs(i + 1), np.array([i]), np.array([0.0]), np.array([1.0]), [{}], capacity=10)
        buf.add_demonstration(obs(i), obs(i + 2), np.array([100 + i]), np.array([-10.0]), np.array([1.0]), [{}],
                              capacity=10, expert=False)
    demos = buf.demonstrations
    assert demos.n_stored == 6 and demos.expert[:6].tolist() == [True, False] * 3
    batch = buf.sample_arrays(64, 0.5, np.random.default_rng(0))  # the ring is empty: every row a kept one
    assert (batch.is_demo == (batch.actions < 100)).all() and batch.is_demo.any() and not batch.is_demo.all()
    assert (batch.rewards[~batch.is_demo] == -10.0).all() and (batch.dones == 1.0).all()
    buf.add(obs(7), obs(8), np.array([7]), np.array([0.0]), np.array([0.0]), [{}])
    mixed = buf.sample_arrays(64, 0.5, np.random.default_rng(1))
    ring = mixed.actions == 7
    assert ring.sum() == 32 and not mixed.is_demo[ring].any()  # the ring's rows are never demonstrations
    back = pickle.loads(pickle.dumps(buf))
    assert back.demonstrations.expert[:6].tolist() == [True, False] * 3 and back.demonstrations._expert
    old = demos.__getstate__()  # a store pickled before the flag existed: every row was the demonstrator's
    del old["expert"], old["_expert"]
    restored = HindsightRelabelReplayBuffer.__new__(HindsightRelabelReplayBuffer)
    restored.__setstate__(old)
    assert restored.expert[:6].all() and restored._expert and len(restored.expert) == 10
