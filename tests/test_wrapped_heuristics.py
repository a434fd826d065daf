"""research/wrapped_heuristics.py and the registry's cell size per name: ``h-d-1cm`` acts at 1 cm cells,
``+shipped-filter`` masks the heuristic's picks that the shipped geometry risk calls risky (and only those), and an
evaluation fingerprints the risk model a named policy's wrapper reads."""

import dataclasses
import json

import gymnasium as gym
import numpy as np
import pytest

import research.wrapped_heuristics as wh
import shelf_env  # noqa: F401  (registers ShelfSort-v0)
from shelf_env import params, policies
from shelf_env.baselines.heuristics import ObservationView
from shelf_env.evaluation import protocol as ev
from shelf_env.fall_filter import FallFilter


def test_a_name_acts_at_its_registered_cell_size():
    assert policies.policy_pixel_size("h-d-1cm+shipped-filter+pick-guard+loop-breaker") == wh.CELL_1CM
    assert policies.policy_pixel_size("h-d+loop-breaker") == params.PIXEL_SIZE
    env = ev.make_env("h-a-1cm+shipped-filter", 3)
    try:
        assert env.observation_space.shape == (4, 40, 60)
    finally:
        env.close()
    for bad in (0.0, -0.01, 1.5, "1cm"):
        with pytest.raises(ValueError, match="pixel_size"):
            policies.register_policy(f"bad-{bad}", lambda env, seed: None, pixel_size=bad)
        assert f"bad-{bad}" not in policies.POLICIES


def test_the_shipped_filter_vetoes_exactly_the_risky_choices_of_the_heuristic():
    env = gym.make("ShelfSort-v0", num_objects=8, object_set="ycb", pixel_size=wh.CELL_1CM)
    try:
        plain = policies.make_policy("h-d-1cm", env)
        wrapped = policies.make_policy("h-d-1cm+shipped-filter", env)
        assert isinstance(wrapped, FallFilter)
        cells = env.unwrapped.rows * env.unwrapped.cols
        changed = 0
        for seed in (1, 2, 9):  # 1 and 9: H-d's choice is risky; 2: it is not
            obs, _ = env.reset(seed=seed)
            risk = wrapped.risk.risk(obs).reshape(-1)
            a, b = int(plain.predict(obs)[0]), int(wrapped.predict(obs)[0])
            assert b < cells and risk[b] < wrapped.risk.threshold  # a pick, not a risky one
            if risk[a] < wrapped.risk.threshold:
                assert b == a  # nothing to veto: the heuristic's own choice
            else:
                changed += 1
        assert changed == 2 and wrapped.stats["masked"] == 3
    finally:
        env.close()
    small = gym.make("ShelfSort-v0", num_objects=3, object_set="ycb")  # 0.5 cm cells: not what the model reads
    try:
        with pytest.raises(ValueError, match="shape"):
            policies.make_policy("h-d+shipped-filter", small)
    finally:
        small.close()


def test_an_evaluation_fingerprints_the_model_a_named_policys_wrapper_reads(tmp_path):
    named = "h-d-1cm+shipped-filter+loop-breaker"
    assert policies.policy_files(named) == [wh.SHIPPED_RISK]
    assert policies.policy_files("h-d-1cm+loop-breaker") == [] and ev.policy_digest("h-d+loop-breaker") == ""
    (tmp_path / "cells").mkdir()
    ev.check_cell_owner(tmp_path, [named, "h-d"], record=True)
    assert [p.name for p in (tmp_path / "cells").iterdir()] == ["h-d-1cm+shipped-filter+loop-breaker.sha256"]
    assert ev.fingerprint_path(tmp_path, named).read_text().strip() == ev.policy_digest(named)
    ev.fingerprint_path(tmp_path, named).write_text("0" * 64 + "\n")  # cells of another risk model
    with pytest.raises(ValueError, match="another"):
        ev.check_cell_owner(tmp_path, [named])


def test_the_risk_trace_changes_no_action_and_counts_the_risky_picks():
    env = gym.make("ShelfSort-v0", num_objects=8, object_set="ycb", pixel_size=wh.CELL_1CM)
    try:
        obs, _ = env.reset(seed=9)  # H-d's choice here is risky (the filter test above)
        plain = int(policies.make_policy("h-d-1cm", env).predict(obs)[0])
        traced = policies.make_policy("h-d-1cm+risk-trace", env)
        assert isinstance(traced, wh.RiskTrace) and not traced.acts_masked  # a heuristic gets no env masks
        assert int(traced.predict(obs, episode_start=np.array([True]))[0]) == plain
        assert traced.stats == {"decisions": 1, "picks": 1, "risky_picks": 1, "no_safe": 0}
        filtered = policies.make_policy("h-d-1cm+shipped-filter+risk-trace", env)
        filtered.predict(obs)
        assert filtered.stats == {"decisions": 1, "picks": 1, "risky_picks": 0, "no_safe": 0}
    finally:
        env.close()


def _cell(folder, policy, outcomes, machine="here"):
    """One cell (N = 8, seed 0) of ``policy`` with (success, actions, failure, fell, risky_picks) per run."""
    records = [ev.EpisodeRecord(policy, "ycb", 8, 0, run, success=s, actions=a, num_unsorted_initial=8, fell=f,
                                noops=0, failure=why, max_repeat=1, machine=machine,
                                policy_stats={"decisions": a, "picks": a, "risky_picks": k, "no_safe": 0})
               for run, (s, a, why, f, k) in enumerate(outcomes)]
    (folder / "cells").mkdir(parents=True, exist_ok=True)
    (folder / "cells" / f"{policy}__ycb__N08__seed0__runs{len(records)}.json").write_text(
        json.dumps([dataclasses.asdict(r) for r in records]))


def test_the_trace_table_checks_the_episodes_against_the_untraced_ones(tmp_path):
    runs = [(True, 9, "", False, 0), (False, 4, "fell", True, 2), (False, 6, "fell", True, 0)]
    _cell(tmp_path / "trace", "h-a-1cm+risk-trace", runs)
    _cell(tmp_path / "played", "h-a-1cm", runs)
    table = wh.trace_table(tmp_path / "trace", tmp_path / "played")
    assert "| h-a-1cm | 3 | 1 | 2 | 19 | 19 | 2 (10.5 %) | 0 (0.0 %) | 1 of 2 | 3 (0) |" in table
    _cell(tmp_path / "played", "h-a-1cm", [runs[0], (False, 5, "fell", True, 2), runs[2]])
    with pytest.raises(ValueError, match="run 1 ended"):
        wh.trace_table(tmp_path / "trace", tmp_path / "played")
    _cell(tmp_path / "played", "h-a-1cm", [runs[0], (False, 5, "fell", True, 2), runs[2]], machine="elsewhere")
    assert "| 1 of 2 | 0 (3) |" in wh.trace_table(tmp_path / "trace", tmp_path / "played")  # counted, not compared
    assert wh.main([str(tmp_path / "trace"), str(tmp_path / "nowhere"), "--out", str(tmp_path / "t.md")]) == 2
    assert not (tmp_path / "t.md").exists()  # nothing written on an error
    assert wh.main([str(tmp_path / "trace"), str(tmp_path / "played"), "--out", str(tmp_path / "t.md")]) == 0
    assert (tmp_path / "t.md").read_text() == wh.trace_table(tmp_path / "trace", tmp_path / "played")


def test_the_push_fallback_pushes_only_where_every_unsorted_objects_candidates_are_masked():
    env = gym.make("ShelfSort-v0", num_objects=5, object_set="ycb", pixel_size=wh.CELL_1CM)
    try:
        obs, _ = env.reset(seed=3)
        base = env.unwrapped
        pusher, plain = wh.AccessibilityPushFallback(env), policies.make_policy("h-a-1cm", env)
        n = int(env.action_space.n)
        everything = np.ones(n, bool)
        assert int(pusher.predict(obs, action_masks=everything)[0]) == int(plain.predict(obs)[0])  # a pick: H-a's
        view = ObservationView.from_observation(obs, pusher.margin_cells)
        unsorted = view.graspable & ~view.sorted_cells
        assert unsorted.any()
        masked = everything.copy()
        masked[base.codec.map_index("pick") * base.rows * base.cols + np.flatnonzero(unsorted)] = False
        first, second = pusher.push_candidates(view)[:2]
        assert int(pusher.predict(obs, action_masks=masked)[0]) == first >= base.rows * base.cols  # a push
        masked[first] = False
        assert int(pusher.predict(obs, action_masks=masked)[0]) == second
        assert pusher.stats == {"push_fallbacks": 2}
        assert int(pusher.predict(obs)[0]) == int(plain.predict(obs)[0])  # no masks: H-a
    finally:
        env.close()


def test_ray_refuses_a_named_policy_whose_wrapper_reads_a_file(tmp_path, capsys):
    pytest.importorskip("ray")
    from shelf_env.cli import evaluate

    args = ["--policies", "h-d-1cm+shipped-filter", "--ns", "3", "--runs", "1", "--seeds", "1",
            "--out", str(tmp_path / "out"), "--backend", "ray"]
    assert evaluate.main(args) == 2
    assert "carries only the checkpoint" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_the_push_fallback_wrapper_overrides_a_checkpoints_choice_only_where_no_candidate_pick_is_left():
    from pixel_envs import ScoresPolicy

    env = gym.make("ShelfSort-v0", num_objects=5, object_set="ycb", pixel_size=wh.CELL_1CM)
    try:
        obs, _ = env.reset(seed=3)
        base = env.unwrapped
        n = int(env.action_space.n)
        scores = np.zeros(n)
        scores[n - 1] = 1.0  # the last push-right cell: what the policy would choose
        wrapped = wh.PushFallback(ScoresPolicy(scores, obs.shape), env)
        everything = np.ones(n, bool)
        assert int(wrapped.predict(obs, action_masks=everything)[0]) == n - 1
        view = ObservationView.from_observation(obs, wrapped.rule.margin_cells)
        masked = everything.copy()
        masked[np.flatnonzero(view.graspable & ~view.sorted_cells)] = False  # the pick map comes first
        assert int(wrapped.predict(obs, action_masks=masked)[0]) == wrapped.rule.push_candidates(view)[0] != n - 1
        assert int(wrapped.predict(obs)[0]) == n - 1  # no masks: nothing to fall back from
        assert wrapped.stats == {"push_fallbacks": 1}
        assert base.codec.map_index("pick") == 0
    finally:
        env.close()
    assert policies.policy_wrappers("m.zip+push-fallback+geometry-filter+pick-guard+loop-breaker") == (
        "m.zip", ("+push-fallback", "+geometry-filter", "+pick-guard", "+loop-breaker"))
