"""The privileged one-step lookahead (`shelf_env.lookahead`): a forked probe reports exactly what the
env's step will do and leaves the env untouched; the lookahead heuristic vetoes the crafted drag."""

from __future__ import annotations

import hashlib

import gymnasium as gym
import numpy as np
import pytest

from shelf_env import evaluation as ev
from shelf_env.heuristics import AccessibilityHeuristic, DistanceHeuristic
from shelf_env.lookahead import LookaheadAccessibility, LookaheadDistance, probe_step
from shelf_env.world import Region
from tests.conftest import REGIONS
from tests.test_closed_loop import DRAG_SCENE

# the drag scene's boxes, both misplaced: H-d goes for the back one first (farther from its region),
# and its carry drags the front one out of the opening
DRAG_REGIONS = [Region(0.0, 0.40, -0.30, -0.12), Region(0.0, 0.40, 0.12, 0.30), Region(0.0, 0.40, -0.09, 0.09)]
SCENE = [(DRAG_SCENE[0][0], 0, 0.30, 0.05, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.05, 0.0)]


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
            obs, reward, terminated, _, info = env.step(action)
            assert (first.obs_sha256, first.reward, first.terminated, first.fell, first.is_success) == (
                sha(obs), reward, terminated, info["fell"], info["is_success"])
            if terminated:
                break
    finally:
        env.close()


def test_lookahead_vetoes_the_pick_that_drags_the_neighbour_out(env):
    obs, _ = env.set_scene(SCENE, DRAG_REGIONS)
    plain = int(DistanceHeuristic(env).predict(obs)[0])
    assert probe_step(env, plain).fell  # H-d's own choice drops the front box
    look = LookaheadDistance(env)
    action = int(look.predict(obs)[0])
    _, row, col = env.decode_action(action)
    assert abs(env.codec.cell_centre(row, col)[0] - 0.06) < 0.04  # the front box instead
    assert look.stats == {"decisions": 1, "probes": 2, "vetoes": 1, "unavoidable": 0}
    _, reward, _, _, info = env.step(action)
    assert not info["fell"] and reward != -10 and len(env.world.objects) == 2


def test_lookahead_keeps_the_base_choice_when_it_is_valid_or_nothing_is(env):
    # only the back box is misplaced: its carry drops the front one, and there is no other pick
    obs, _ = env.set_scene([(DRAG_SCENE[0][0], 0, 0.30, 0.0, 0.0), (DRAG_SCENE[1][0], 1, 0.06, 0.0, 0.0)], REGIONS)
    look = LookaheadAccessibility(env)
    assert int(look.predict(obs)[0]) == int(AccessibilityHeuristic(env).predict(obs)[0])
    assert look.stats == {"decisions": 1, "probes": 1, "vetoes": 0, "unavoidable": 1}
    obs, _ = env.reset(seed=5, options={"num_objects": 2})  # its first H-a pick is fine: one probe
    look = LookaheadAccessibility(env)
    action = int(look.predict(obs)[0])
    assert probe_step(env, action).valid
    assert action == int(AccessibilityHeuristic(env).predict(obs)[0])
    assert look.stats == {"decisions": 1, "probes": 1, "vetoes": 0, "unavoidable": 0}


def test_lookahead_policies_are_named_policies_of_the_evaluation():
    records = ev.evaluate_cell("h-a-lookahead", num_objects=2, seed=0, runs=1, object_set="train")
    assert records[0].policy == "h-a-lookahead" and records[0].actions >= 1
    assert ev.check_policy("h-d-lookahead") == ("pick", "push")


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
