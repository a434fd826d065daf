"""LoopBreaker: bans a place after max_visits actions near it, per map and per episode; respects
the caller's masks; falls back where everything is banned; and its evaluation policy name."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.loop_breaker import LoopBreaker
from shelf_env.evaluation import protocol as ev

MAPS, H, W = 2, 4, 5


class FixedScores:
    """A greedy pixel policy whose Q-values never change: without a breaker it repeats one action forever."""

    observation_space = spaces.Box(0, 255, (3, H, W), np.uint8)
    action_space = spaces.Discrete(MAPS * H * W)

    def __init__(self, scores: np.ndarray) -> None:
        self.scores = np.asarray(scores, dtype=float).reshape(-1)
        self.calls = 0

    def predict(self, obs, state=None, episode_start=None, deterministic=True, action_masks=None):
        self.calls += 1
        batch = np.asarray(obs).ndim == 4
        masks = np.ones((len(obs) if batch else 1, self.scores.size), bool) if action_masks is None \
            else np.asarray(action_masks, bool).reshape(-1, self.scores.size)
        actions = np.where(masks, self.scores, -np.inf).argmax(axis=1)
        return (actions if batch else actions[0]), state


def index(m: int, r: int, c: int) -> int:
    return (m * H + r) * W + c


def ramp() -> np.ndarray:
    """Best at map 0, cell (1, 1); every other cell worse the further (by index) from it."""
    return -np.abs(np.arange(MAPS * H * W) - index(0, 1, 1)).astype(float)


OBS = np.zeros((3, H, W), np.uint8)


def test_a_repeated_action_is_banned_after_max_visits_and_the_next_best_taken():
    breaker = LoopBreaker(FixedScores(ramp()), max_visits=3, radius=0)
    actions = [int(breaker.predict(OBS, deterministic=True)[0]) for _ in range(5)]
    best = index(0, 1, 1)
    assert actions[:3] == [best] * 3  # allowed until it has been executed max_visits times
    assert actions[3] in (best - 1, best + 1) and actions[3] != best  # the next-best pixel
    assert breaker.banned()[best] and breaker.banned().sum() == 1
    assert breaker.stats == {"bans": 1, "redirects": 2}


def test_radius_bans_the_neighbourhood_of_one_map_only():
    breaker = LoopBreaker(FixedScores(ramp()), max_visits=3, radius=1)
    for _ in range(3):
        breaker.predict(OBS, deterministic=True)
    banned = breaker.banned().reshape(MAPS, H, W)
    assert banned[0, 0:3, 0:3].all() and banned.sum() == 9  # the 3x3 patch around (1, 1) of map 0
    action = int(breaker.predict(OBS, deterministic=True)[0])
    m, rest = divmod(action, H * W)
    assert (m, *divmod(rest, W)) not in {(0, r, c) for r in range(3) for c in range(3)}
    # three actions spread over a patch ban its middle too (the loop that drifts by a pixel)
    drift = LoopBreaker(FixedScores(ramp()), max_visits=3, radius=1)
    drift._visits = [np.zeros((MAPS, H, W), np.int32)]
    for r, c in ((2, 2), (2, 3), (3, 2)):
        drift._visits[0][1, r, c] += 1
    assert drift.banned().reshape(MAPS, H, W)[1, 2, 2] and not drift.banned().reshape(MAPS, H, W)[0].any()


def test_the_callers_masks_hold_and_everything_banned_falls_back_to_them():
    masks = np.zeros(MAPS * H * W, bool)
    masks[[index(0, 1, 1), index(1, 3, 4)]] = True
    breaker = LoopBreaker(FixedScores(ramp()), max_visits=1, radius=0)
    first = int(breaker.predict(OBS, deterministic=True, action_masks=masks)[0])
    second = int(breaker.predict(OBS, deterministic=True, action_masks=masks)[0])
    assert (first, second) == (index(0, 1, 1), index(1, 3, 4))  # never a masked-out action
    third = int(breaker.predict(OBS, deterministic=True, action_masks=masks)[0])
    assert third == index(0, 1, 1)  # both allowed actions banned: the caller's masks, unchanged


def test_episode_start_and_reset_clear_the_memory_per_env():
    breaker = LoopBreaker(FixedScores(ramp()), max_visits=1, radius=0)
    batch = np.zeros((2, 3, H, W), np.uint8)
    best = index(0, 1, 1)
    assert breaker.predict(batch, deterministic=True)[0].tolist() == [best, best]
    assert best not in breaker.predict(batch, deterministic=True)[0].tolist()
    # env 1 starts a new episode: its bans are gone, env 0's stay
    actions = breaker.predict(batch, episode_start=np.array([False, True]), deterministic=True)[0]
    assert actions[0] != best and actions[1] == best
    breaker.reset()
    assert not breaker.banned(0).any() and not breaker.banned(1).any()
    assert int(breaker.predict(OBS, deterministic=True)[0]) == best


def test_bad_input_is_refused_with_a_clear_error():
    policy = FixedScores(ramp())
    with pytest.raises(ValueError, match="max_visits must be an integer >= 1"):
        LoopBreaker(policy, max_visits=0)
    with pytest.raises(ValueError, match="radius must be an integer >= 0"):
        LoopBreaker(policy, radius=-1)

    class NoMasks(FixedScores):
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return super().predict(obs, state, episode_start, deterministic)

    with pytest.raises(ValueError, match="takes none"):
        LoopBreaker(NoMasks(ramp()))

    class NotPixels(FixedScores):
        action_space = spaces.Discrete(7)

    with pytest.raises(ValueError, match="not whole 4x5 maps"):
        LoopBreaker(NotPixels(ramp()))
    with pytest.raises(ValueError, match="action_masks has 3 entries"):
        LoopBreaker(policy).predict(OBS, action_masks=np.ones(3, bool))
    with pytest.raises(ValueError, match="episode_start has 2 entries"):
        LoopBreaker(policy).predict(OBS, episode_start=np.array([True, False]))


def test_the_evaluation_plays_a_checkpoint_under_a_loop_breaker(tmp_path):
    """``PATH+loop-breaker``: its own label and cells, the checkpoint's layout, a breaker that
    forgets each episode (every run of a cell plays as it would alone)."""
    env = gym.make("ShelfSort-v0", primitives=("pick",))
    # masked=False: the paper's all-pixel argmax, which an untrained net spends on one empty cell
    model = PixelDoubleDQN("FCNPolicy", env, masked=False, policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)),
                           seed=0)
    model.save(tmp_path / "s.zip")
    env.close()
    policy = str(tmp_path / "s.zip") + ev.LOOP_BREAKER
    assert ev.policy_label(policy) == "s+loop-breaker" and ev.check_policy(policy) == ("pick",)
    assert ev.cell_path(tmp_path, policy, "ycb", 3, 0, 1).name == "s+loop-breaker__ycb__N03__seed0__runs1.json"
    env = ev.make_env(policy, 2, "train")
    try:
        agent = ev.make_policy(policy, env)
        assert isinstance(agent, LoopBreaker) and not ev.takes_action_masks(agent)  # as the model it wraps
        unbroken = ev.run_episode(env, ev.make_policy(policy[:-len(ev.LOOP_BREAKER)], env), ev.scene_seed(0, 2, 1))
        alone = ev.run_episode(env, ev.make_policy(policy, env), ev.scene_seed(0, 2, 1))
        together = [ev.run_episode(env, agent, ev.scene_seed(0, 2, run)) for run in (0, 1)]
    finally:
        env.close()
    assert together[1] == alone  # the first episode's bans were forgotten at the second's start
    assert unbroken["max_repeat"] >= 2 * ev.LOOP_REPEAT  # one cell again and again (40 times here)
    assert alone["max_repeat"] <= agent.max_visits and alone["policy_stats"]["bans"] >= 1


def test_heuristics_choose_among_the_allowed_cells_and_run_under_a_breaker():
    """H-d / H-a take masks (a LoopBreaker's) without being given the env's by an evaluation: a
    masked-out choice moves to another candidate cell; masks that leave no candidate change nothing."""
    from shelf_env.baselines.heuristics import DistanceHeuristic

    env = gym.make("ShelfSort-v0", num_objects=4)
    try:
        obs, _ = env.reset(seed=ev.scene_seed(0, 4, 0))
        h_d = DistanceHeuristic(env)
        assert not ev.takes_action_masks(h_d) and ev.predict_takes(h_d, "action_masks")
        first = int(h_d.predict(obs)[0])
        masks = np.ones(env.action_space.n, bool)
        masks[first] = False
        second = int(h_d.predict(obs, action_masks=masks)[0])
        codec = env.unwrapped.codec
        assert second != first and codec.decode(second)[0] == "pick" and masks[second]
        picks_only_first = np.zeros(env.action_space.n, bool)
        picks_only_first[codec.encode("push_left", 0, 0)] = True  # no candidate pick allowed
        assert int(h_d.predict(obs, action_masks=picks_only_first)[0]) == first
        with pytest.raises(ValueError, match="action_masks has 3 entries"):
            h_d.predict(obs, action_masks=np.ones(3, bool))
        agent = ev.make_policy("h-a" + ev.LOOP_BREAKER, env)
        assert isinstance(agent, LoopBreaker) and not ev.takes_action_masks(agent)
        assert ev.policy_label("h-a" + ev.LOOP_BREAKER) == "h-a+loop-breaker"
        assert ev.check_policy("h-a" + ev.LOOP_BREAKER) == ("pick", "push")
        assert [int(agent.predict(obs, deterministic=True)[0]) for _ in range(4)][3] != \
            int(agent.policy.predict(obs)[0])  # the fourth repeat is redirected
    finally:
        env.close()
