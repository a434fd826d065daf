"""The planning teacher (`shelf_env.privileged.planning`): a rollout reports exactly what playing it out does,
leaves the env untouched, and the teacher sorts while recording a value in the env's units."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from shelf_env.evaluation.protocol import run_episode, scene_seed
from shelf_env.privileged import dataset
from shelf_env.privileged.lookahead import LookaheadHeuristic, digest
from shelf_env.privileged.planning import PlanningTeacher, rollout, unsorted_value


def test_a_rollout_is_what_playing_it_out_does_and_leaves_the_env_untouched() -> None:
    env = gym.make("ShelfSort-v0", num_objects=3, object_set="train", pixel_size=0.01)
    try:
        obs, info = env.reset(seed=5)
        before = digest(obs)
        first = int(np.flatnonzero(env.unwrapped.action_masks())[0])
        result = rollout(env, first, horizon=3, gamma=0.9)
        assert digest(env.unwrapped.observation) == before  # the parent's simulation did not move
        # the same rollout played in the parent
        obs, reward, terminated, truncated, info = env.step(first)
        score, discount, steps = reward, 0.9, 1
        policy = LookaheadHeuristic(env)
        while not (terminated or truncated) and steps < 3:
            obs, reward, terminated, truncated, info = env.step(int(policy.predict(obs)[0]))
            score, discount, steps = score + discount * reward, discount * 0.9, steps + 1
        if not terminated:
            score += discount * unsorted_value(info["num_objects"] - info["num_sorted"], 0.9)
        assert result["steps"] == steps and result["score"] == pytest.approx(score)
        assert result["actions"] >= steps
    finally:
        env.close()


def test_the_planner_sorts_and_records_its_value() -> None:
    env = gym.make("ShelfSort-v0", num_objects=3, object_set="train", pixel_size=0.01)
    try:
        teacher = PlanningTeacher(env, horizon=2, max_candidates=3)
        record = run_episode(env, teacher, scene_seed(0, 3, 1))
        assert record["success"]
        stats = record["policy_stats"]
        assert stats["decisions"] >= 1 and stats["rollouts"] >= stats["planned"] >= 1
        assert stats["actions"] >= stats["probes"] + stats["rollouts"]
        assert teacher.value is not None and -10.0 <= teacher.value <= 0.0
    finally:
        env.close()
    assert unsorted_value(0, 0.9) == 0.0 and unsorted_value(1, 0.9) == pytest.approx(-1.0)
    with pytest.raises(ValueError, match="horizon >= 1"):
        PlanningTeacher(gym.make("ShelfSort-v0", num_objects=1), horizon=0)


def test_a_collection_with_the_planner_records_the_teacher_value(tmp_path) -> None:
    assert dataset.collect(tmp_path, ns=(2,), model_path=None, episodes_per_shard=1, max_shards=1, max_probes=4,
                           teacher="h-d-planner") == 1
    shard = dataset.load_shard(dataset.shard_path(tmp_path, 0, 0))
    assert shard.meta["teacher"] == "h-d-planner"
    values = shard.arrays["teacher_value"]
    assert np.isfinite(values).all() and (values <= 0).all()
    with pytest.raises(ValueError, match="unknown teacher"):
        dataset.collect(tmp_path, ns=(2,), model_path=None, max_shards=1, teacher="oracle")
