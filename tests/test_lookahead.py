"""The privileged one-step lookahead (`shelf_env.privileged.lookahead`): a forked probe reports exactly what the
env's step will do and leaves the env untouched; the lookahead heuristic vetoes the crafted drag."""

from __future__ import annotations

import hashlib

import gymnasium as gym
import numpy as np
import pytest

from research.lookahead_falls import invalid_step_table
from shelf_env import params
from shelf_env.baselines.heuristics import AccessibilityHeuristic, DistanceHeuristic, ObservationView
from shelf_env.evaluation import protocol as ev
from shelf_env.privileged import lookahead
from shelf_env.privileged.lookahead import (
    STAT_KEYS,
    FallGuard,
    LookaheadAccessibility,
    LookaheadDistance,
    LookaheadHeuristic,
    Outcome,
    probe_outcome,
    probe_step,
)
from shelf_env.world.cabinet import Region
from tests.conftest import REGIONS
from tests.test_closed_loop import DRAG_SCENE

# the drag scene's boxes, both misplaced: H-d goes for the back one first (farther from its region),
# and its carry drags the front one out of the opening
DRAG_REGIONS = [Region(0.0, 0.40, -0.30, -0.12), Region(0.0, 0.40, 0.12, 0.30), Region(0.0, 0.40, -0.09, 0.09)]
SCENE = [(DRAG_SCENE[0][0], 0, 0.30, 0.05, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.05, 0.0)]
# with REGIONS only the back box is misplaced, and its carry drops the sorted front one
DEADLOCK = [(DRAG_SCENE[0][0], 0, 0.30, 0.0, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.0, 0.0)]


def stats(look: LookaheadHeuristic) -> dict[str, int]:
    """The lookahead's non-zero counters."""
    assert set(look.stats) == set(STAT_KEYS)
    return {key: value for key, value in look.stats.items() if value}


def sha(obs: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(obs).tobytes()).hexdigest()


def test_probe_reports_exactly_what_the_step_does_and_leaves_the_env_untouched():
    env = gym.make("ShelfSort-v0", num_objects=4).unwrapped
    try:
        obs, _ = env.reset(seed=3)
        for _ in range(2):
            action = int(AccessibilityHeuristic(env).predict(obs)[0])
            first, again = probe_step(env, action), probe_step(env, action)
            assert first == again  # the first probe changed nothing in the parent
            assert sha(first.next_obs) == first.obs_sha256 and first.next_obs.shape == obs.shape
            obs, reward, terminated, _, info = env.step(action)
            assert (first.obs_sha256, first.reward, first.terminated, first.fell, first.is_success) == (
                sha(obs), reward, terminated, info["fell"], info["is_success"])
            if terminated:
                break
    finally:
        env.close()


def test_probe_outcome_is_probe_step_without_the_image():
    env = gym.make("ShelfSort-v0", num_objects=6, object_set="train", pixel_size=0.01).unwrapped
    try:
        obs, _ = env.reset(seed=11)
        allowed = np.flatnonzero(env.action_masks())
        actions = [int(a) for a in np.random.default_rng(0).choice(allowed, size=6, replace=False)]
        outcomes = [(probe_step(env, a), probe_outcome(env, a)) for a in actions]
        for full, blind in outcomes:
            assert (blind.reward, blind.terminated, blind.fell, blind.is_success, blind.num_sorted) == (
                full.reward, full.terminated, full.fell, full.is_success, full.num_sorted)
            assert blind.obs_sha256 == "" and blind.next_obs is None and full.num_sorted is not None
        assert len({o.valid for _, o in outcomes}) == 2 or len({o.num_sorted for _, o in outcomes}) > 1  # not all alike
        assert sha(env.observation) == sha(obs)  # the env is untouched
        # ... and its outcome is the real step's
        _, reward, terminated, _, info = env.step(actions[0])
        assert (outcomes[0][1].reward, outcomes[0][1].terminated, outcomes[0][1].fell) == (
            reward, terminated, info["fell"])
        # step_outcome leaves an env without an observation: only a thrown-away copy may call it
        env.reset(seed=11)
        assert env.step_outcome(actions[1])["num_sorted"] == outcomes[1][1].num_sorted
        with pytest.raises(RuntimeError, match="reset"):
            env.step(actions[1])
    finally:
        env.close()


def test_lookahead_vetoes_the_pick_that_drags_the_neighbour_out(env):
    obs, _ = env.set_scene(SCENE, DRAG_REGIONS)
    plain = int(DistanceHeuristic(env).predict(obs)[0])
    assert probe_step(env, plain).fell  # H-d's own choice drops the front box
    look = LookaheadDistance(env)
    assert look.counterfactuals() == []  # no decision yet
    action = int(look.predict(obs)[0])
    _, row, col = env.decode_action(action)
    assert abs(env.codec.cell_centre(row, col)[0] - 0.06) < 0.04  # the front box instead
    assert stats(look) == {"decisions": 1, "probes": 2, "vetoes": 1}
    # the vetoed pick is its counterfactual: the terminal step the env would have returned
    [(rejected, reward, next_obs)] = look.counterfactuals()
    assert rejected == plain and reward == params.REWARD_INVALID
    assert sha(next_obs) == probe_step(env, plain).obs_sha256 != sha(obs)
    _, reward, _, _, info = env.step(action)
    assert not info["fell"] and reward != -10 and len(env.world.objects) == 2


def test_lookahead_keeps_the_base_choice_when_it_is_valid_or_nothing_is(env):
    # only the back box is misplaced: its carry drops the front one, and there is no other pick
    obs, _ = env.set_scene(DEADLOCK, REGIONS)
    look = LookaheadAccessibility(env, pushes=False)
    assert int(look.predict(obs)[0]) == int(AccessibilityHeuristic(env).predict(obs)[0])
    assert stats(look) == {"decisions": 1, "probes": 1, "unavoidable": 1}
    assert look.counterfactuals() == []  # its one probed pick is the one it takes
    obs, _ = env.reset(seed=5, options={"num_objects": 2})  # its first H-a pick is fine: one probe
    look = LookaheadAccessibility(env)
    action = int(look.predict(obs)[0])
    assert probe_step(env, action).valid
    assert action == int(AccessibilityHeuristic(env).predict(obs)[0])
    assert stats(look) == {"decisions": 1, "probes": 1}


def test_lookahead_frees_the_deadlock_with_a_push_that_keeps_the_scene_valid(env):
    obs, _ = env.set_scene(DEADLOCK, REGIONS)  # every pick drops something
    look = LookaheadAccessibility(env)
    view = ObservationView.from_observation(obs, look.margin_cells)
    pushes = look.push_candidates(view)
    assert len(pushes) == 4 and {env.codec.decode(a)[0] for a in pushes} == {"push_left", "push_right"}
    action = int(look.predict(obs)[0])
    assert action in pushes and stats(look)["push_rescues"] == 1
    assert stats(look)["probes"] == 1 + pushes.index(action) + 1  # the one pick, then the pushes up to it
    for earlier in pushes[:pushes.index(action)]:  # the pushes tried before it were invalid or moved nothing
        outcome = probe_step(env, earlier)
        assert not outcome.valid or outcome.obs_sha256 == sha(obs)
    next_obs, reward, terminated, _, info = env.step(action)
    assert not info["fell"] and reward != -10 and not terminated and sha(next_obs) != sha(obs)
    assert LookaheadAccessibility(env, pushes=False).push_candidates(view) == pushes  # the option gates their use
    pick_only = gym.make("ShelfSort-v0", num_objects=2, primitives=("pick",)).unwrapped
    try:
        pick_only.reset(seed=0)
        assert LookaheadAccessibility(pick_only).push_candidates(view) == []  # S's layout has no push
    finally:
        pick_only.close()


def test_lookahead_probes_the_uncovering_picks_when_every_visible_object_looks_sorted(env, monkeypatch):
    # both boxes sorted (class 1's region is the middle strip): H-a uncovers with the front box
    obs, _ = env.set_scene([(DRAG_SCENE[0][0], 1, 0.30, 0.0, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.0, 0.0)], REGIONS)
    look = LookaheadAccessibility(env)
    view = ObservationView.from_observation(obs, look.margin_cells)
    assert look.candidates(view) == []
    front, back = look.uncover_candidates(view)
    assert front == look.base.choose(view)  # the base's own uncovering pick comes first
    assert env.codec.cell_centre(*front)[0] < 0.1 < 0.25 < env.codec.cell_centre(*back)[0]
    assert probe_step(env, look._pick(*front)).valid and probe_step(env, look._pick(*back)).fell  # the real outcomes
    assert int(look.predict(obs)[0]) == look._pick(*front)
    assert stats(look) == {"uncover_decisions": 1, "probes": 1}
    # were the front pick the invalid one, the back box would be taken, and the veto counted
    invalid = Outcome(-10.0, True, True, False, "")
    monkeypatch.setattr(lookahead, "probe_step", lambda _env, action: invalid if action == look._pick(*front)
                        else Outcome(0.0, False, False, False, ""))
    look = LookaheadAccessibility(env)
    assert int(look.predict(obs)[0]) == look._pick(*back)
    assert stats(look) == {"uncover_decisions": 1, "uncover_vetoes": 1, "probes": 2}
    monkeypatch.setattr(lookahead, "probe_step", lambda _env, action: invalid)  # nothing valid: the base's choice
    look = LookaheadAccessibility(env)
    assert int(look.predict(obs)[0]) == look._pick(*front)
    assert stats(look) == {"uncover_decisions": 1, "uncover_unavoidable": 1,
                           "probes": 2 + len(look.push_candidates(view))}  # both picks, then every push


def test_lookahead_policies_are_named_policies_of_the_evaluation_with_stats_per_episode():
    records = ev.evaluate_cell("h-a-lookahead", num_objects=2, seed=0, runs=2, object_set="train")
    assert records[0].policy == "h-a-lookahead" and records[0].actions >= 1
    assert ev.check_policy("h-d-lookahead") == ("pick", "push")
    for r in records:  # each episode's own counters, not the policy's running totals
        assert set(r.policy_stats) == set(STAT_KEYS)
        steps = r.policy_stats["decisions"] + r.policy_stats["uncover_decisions"]
        assert 1 <= steps <= r.actions and r.policy_stats["probes"] >= steps
    assert ev.evaluate_cell("h-a", num_objects=1, seed=0, runs=1, object_set="train")[0].policy_stats == {}


def test_invalid_step_table_counts_how_the_invalid_episodes_ended():
    def record(run, failure, **counts):
        return ev.EpisodeRecord("h-d-lookahead", "ycb", 8, 0, run, failure == "", 4, 8, failure == "fell",
                                failure=failure, policy_stats={**dict.fromkeys(STAT_KEYS, 0), **counts})
    records = [record(0, "", decisions=4, vetoes=2, probes=8), record(1, "fell", decisions=4, unavoidable=1, probes=9),
               record(2, "fell", uncover_decisions=4, uncover_unavoidable=1, uncover_vetoes=1, probes=7),
               record(3, "unstable", decisions=4, unavoidable=1, probes=4),
               record(4, "timeout", decisions=4, push_rescues=2, probes=4),
               ev.EpisodeRecord("h-d", "ycb", 8, 0, 0, False, 4, 8, True, failure="fell")]  # no stats: left out
    table = invalid_step_table(records)
    assert "| h-d-lookahead | 8 | 5 | 3 | 2 | 1 | 0 | 0.60 | 0.40 | 1.60 |" in table and "| h-d |" not in table
    with pytest.raises(ValueError, match="lookahead stats"):
        invalid_step_table(records[-1:])


def test_bad_input():
    env = gym.make("ShelfSort-v0", num_objects=1).unwrapped
    try:
        with pytest.raises(ValueError, match="max_probes"):
            LookaheadAccessibility(env, max_probes=0)
        env.reset(seed=0)
        with pytest.raises(RuntimeError, match="action 999999999"):
            probe_step(env, 999_999_999)
    finally:
        env.close()
    with pytest.raises(ValueError, match="ShelfSort-v0"):
        probe_step(gym.make("CartPole-v1"), 0)
    with pytest.raises(RuntimeError, match="closed"):
        probe_step(env, 0)


def test_fall_guard_replaces_the_dragging_pick_by_the_teachers_and_reports_the_correction(env):
    obs, _ = env.set_scene(SCENE, DRAG_REGIONS)
    assert np.array_equal(env.observation, obs)  # what the guard's teacher decides on
    plain = int(DistanceHeuristic(env).predict(obs)[0])
    vetoed = probe_step(env, plain)
    assert vetoed.fell  # the learner's action here would drop the front box
    teacher_choice = int(LookaheadDistance(env).predict(obs)[0])
    guard = FallGuard(env)  # H-d with the lookahead by default
    obs, reward, _, _, info = guard.step(plain)
    report = info["correction"]
    assert (report["action"], report["executed"]) == (plain, teacher_choice) and teacher_choice != plain
    assert report["reward"] == params.REWARD_INVALID and report["terminated"]
    assert sha(report["next_obs"]) == vetoed.obs_sha256  # what the vetoed step would have returned
    assert not info["fell"] and reward != params.REWARD_INVALID and len(env.world.objects) == 2
    assert guard.stats == {"steps": 1, "corrections": 1, "probes": 3}  # its probe, then the teacher's two
    # a valid action is executed as given: one probe, no report, the step the env would take
    action = int(LookaheadDistance(env).predict(obs)[0])
    expected = probe_step(env, action)
    assert expected.valid
    obs, reward, terminated, _, info = guard.step(action)
    assert "correction" not in info and (sha(obs), reward, terminated) == (
        expected.obs_sha256, expected.reward, expected.terminated)
    assert guard.stats == {"steps": 2, "corrections": 1, "probes": 4}
    assert np.array_equal(env.observation, obs)
    fresh = gym.make("ShelfSort-v0", num_objects=1).unwrapped
    try:
        with pytest.raises(RuntimeError, match="call reset"):
            fresh.observation  # noqa: B018  (the property raises)
    finally:
        fresh.close()
