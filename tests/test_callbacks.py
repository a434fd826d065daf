"""CurriculumCallback: stage changes, ε restarts, several envs, resume after save/load; TensorBoard tags."""

import glob

import pytest
from pixel_envs import CoinEnv
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env

from sb3_pixeldqn import CurriculumCallback, PixelDoubleDQN

KW = dict(policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)), learning_starts=10**6, buffer_size=100,
          exploration_timesteps=100, seed=0)


class Recorder(BaseCallback):
    """Records (timestep, episode N, ε) at every episode end."""

    def __init__(self) -> None:
        super().__init__()
        self.episodes: list[tuple[int, int, float]] = []

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"]):
            if done:
                self.episodes.append((self.num_timesteps, info["num_objects"], self.model.exploration_rate))
        return True


def test_advances_after_window_of_successes_and_restarts_epsilon():
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=1.0), **KW)
    curriculum, rec = CurriculumCallback(window=5, max_value=3), Recorder()
    model.learn(30, callback=CallbackList([curriculum, rec]))
    ns = [n for _, n, _ in rec.episodes]
    # 5 successes at N=1, then the first N=2 episode, 1 stale one at the old N, 5 counted at N=2, ...
    assert ns[:5] == [1] * 5 and ns[5] == 1 and ns[6:11] == [2] * 5 and ns[11] == 2 and ns[12] == 3
    assert curriculum.value == 3 == model.curriculum_state["value"]  # capped at max_value
    assert [n for _, n in curriculum.history] == [1, 2, 3]
    # ε restarts at each stage change (the 5th success of a stage resets it to 0.8 before the next ε update)
    eps_at_change = [e for t, n, e in rec.episodes if t in (curriculum.history[1][0], curriculum.history[2][0])]
    assert all(e == pytest.approx(0.8) for e in eps_at_change)
    assert model.stage_timesteps < 30


def test_does_not_advance_below_threshold():
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=0.5), **KW)
    curriculum = CurriculumCallback(window=10, threshold=0.9)
    model.learn(60, callback=curriculum)
    assert curriculum.value == 1 and model.stage_timesteps == 60


def test_min_stage_timesteps_holds_a_stage():
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=1.0), **KW)
    curriculum = CurriculumCallback(window=5, max_value=3, min_stage_timesteps=12)
    model.learn(30, callback=curriculum)
    assert [t for t, _ in curriculum.history] == [0, 12, 24]


def test_max_stage_timesteps_promotes_a_stage_that_cannot_pass(tmp_path):
    # p_success 0.5 never passes a 90 % gate: only the cap promotes, every 15 steps, up to max_value
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=0.5), **KW)
    curriculum = CurriculumCallback(window=10, threshold=0.9, max_value=3, max_stage_timesteps=15)
    model.learn(100, callback=curriculum)
    assert curriculum.history == [[0, 1], [15, 2], [30, 3]]
    assert curriculum.capped == [15, 30] == model.curriculum_state["capped"]
    # the last stage is capped too: after 15 steps at N = 3 the curriculum is over and training stops
    assert model.num_timesteps == 45 == curriculum.finished == model.curriculum_state["finished"]
    assert curriculum.over()
    # the cap survives save/load: a resumed run knows which stages were capped, and that it is over
    model.save(tmp_path / "m.zip")
    loaded = PixelDoubleDQN.load(tmp_path / "m.zip", env=CoinEnv(p_success=0.5))
    resumed = CurriculumCallback(window=10, threshold=0.9, max_value=3, max_stage_timesteps=15)
    loaded.learn(50, callback=resumed, reset_num_timesteps=False)
    assert resumed.capped == [15, 30] and resumed.value == 3
    assert loaded.num_timesteps == 46 and resumed.finished == 45  # stopped at its first step
    # resumed with a longer cap, the last stage goes on until that cap
    longer = PixelDoubleDQN.load(tmp_path / "m.zip", env=CoinEnv(p_success=0.5))
    more = CurriculumCallback(window=10, threshold=0.9, max_value=3, max_stage_timesteps=20)
    longer.learn(50, callback=more, reset_num_timesteps=False)
    assert longer.num_timesteps == 50 == more.finished and more.history[-1] == [30, 3]


def test_an_uncapped_curriculum_never_ends_training():
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=1.0), **KW)
    curriculum = CurriculumCallback(window=5, max_value=2)
    model.learn(40, callback=curriculum)
    assert curriculum.value == 2 and model.num_timesteps == 40
    assert curriculum.finished is None and not curriculum.over()


def test_max_stage_timesteps_leaves_passing_stages_alone():
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=1.0), **KW)
    curriculum = CurriculumCallback(window=5, max_value=3, max_stage_timesteps=100)
    model.learn(30, callback=curriculum)
    assert curriculum.value == 3 and curriculum.capped == []


@pytest.mark.parametrize("low, high", [(-1, 0), (0, -5), (20, 10)])
def test_bad_stage_bounds_are_refused(low, high):
    with pytest.raises(ValueError, match="max_stage_timesteps"):
        CurriculumCallback(min_stage_timesteps=low, max_stage_timesteps=high)


def test_several_envs_all_get_the_new_n():
    env = make_vec_env(lambda: CoinEnv(p_success=1.0), n_envs=3)
    model = PixelDoubleDQN("FCNPolicy", env, **KW)
    curriculum, rec = CurriculumCallback(window=6, max_value=4), Recorder()
    model.learn(60, callback=CallbackList([curriculum, rec]))
    assert curriculum.value == 4
    assert env.get_attr("num_objects") == [4, 4, 4]
    first_n4 = min(t for t, n, _ in rec.episodes if n == 4)
    assert first_n4 > curriculum.history[-1][0]


def test_resumes_at_stage_and_epsilon_after_save_load(tmp_path):
    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=1.0), **KW)
    model.learn(14, callback=CurriculumCallback(window=5, max_value=8))
    stage, eps, stage_steps = model.curriculum_state["value"], model.exploration_rate, model.stage_timesteps
    assert stage == 3
    model.save(tmp_path / "m.zip")

    loaded = PixelDoubleDQN.load(tmp_path / "m.zip", env=CoinEnv(p_success=0.0))
    assert loaded.curriculum_state["value"] == 3 and loaded.exploration_rate == pytest.approx(eps)
    rec = Recorder()
    loaded.learn(4, callback=CallbackList([CurriculumCallback(window=5, max_value=8), rec]), reset_num_timesteps=False)
    assert [n for _, n, _ in rec.episodes] == [3, 3, 3, 3]  # first episode already at the saved stage
    assert loaded.stage_timesteps == stage_steps + 4
    assert loaded.num_timesteps == 18


def test_tensorboard_gets_the_promised_scalars(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    model = PixelDoubleDQN("FCNPolicy", CoinEnv(p_success=1.0), tensorboard_log=str(tmp_path),
                           **{**KW, "learning_starts": 5})
    model.learn(40, callback=CurriculumCallback(window=5), log_interval=2, progress_bar=True)
    (run,) = glob.glob(str(tmp_path / "PixelDoubleDQN_*"))
    events = EventAccumulator(run)
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"train/loss", "rollout/success_rate", "rollout/exploration_rate", "curriculum/num_objects"} <= tags
    assert max(e.value for e in events.Scalars("curriculum/num_objects")) >= 2


def test_bad_curriculum_arguments():
    with pytest.raises(ValueError):
        CurriculumCallback(start_value=5, max_value=3)
    with pytest.raises(ValueError):
        CurriculumCallback(threshold=1.5)


def test_greedy_check_action_limit_may_grow_with_the_stage():
    """eval_max_actions as a function of N: an episode that needs 2 N actions passes a 2 N limit and
    fails a fixed limit below it (it is cut and counted as failed)."""
    from pixel_envs import FindTheSquareEnv

    class SlowEnv(FindTheSquareEnv):
        """Succeeds after exactly 2 N steps, whatever the actions."""

        def reset(self, *, seed=None, options=None):
            self.t = 0
            return super().reset(seed=seed, options=options)

        def step(self, action):
            self.t += 1
            done = self.t >= 2 * self.num_objects
            return self._obs(), 0.0, done, False, {"is_success": done, "num_objects": self.num_objects}

    model = PixelDoubleDQN("FCNPolicy", SlowEnv(), **KW)
    for limit, expected in ((lambda n: 2 * n, 1.0), (5, 0.0), (None, 1.0)):
        cb = CurriculumCallback(start_value=3, max_value=3, gate="greedy", eval_env=SlowEnv(), eval_episodes=2,
                                eval_max_actions=limit)
        cb.init_callback(model)
        cb.value = 3
        assert cb.greedy_success() == expected


def test_q_map_images_reach_tensorboard(tmp_path):
    from pixel_envs import FindTheSquareEnv
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from sb3_pixeldqn import QMapImageCallback

    kw = {**KW, "policy_kwargs": dict(maps=[("pick", 0), ("push", 0), ("push", 180)], widths=(4, 8, 8))}
    model = PixelDoubleDQN("FCNPolicy", FindTheSquareEnv(n_maps=3), tensorboard_log=str(tmp_path), **kw)
    model.learn(12, callback=QMapImageCallback(every=4), log_interval=1)
    (run,) = glob.glob(str(tmp_path / "PixelDoubleDQN_*"))
    events = EventAccumulator(run, size_guidance={"images": 0})
    events.Reload()
    tags = set(events.Tags()["images"])
    assert {"images/observation", "images/q_pick", "images/q_push", "images/q_push_180"} <= tags
    (first, *_) = events.Images("images/q_pick")
    assert first.width == 20 and first.height == 12
    with pytest.raises(ValueError, match="every must be >= 1"):
        QMapImageCallback(every=0)
