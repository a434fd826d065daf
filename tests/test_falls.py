"""The greedy fall rate per action: the probed run agrees with the real greedy episode up to its first
rescue, counts every invalid action it rescues, and resumes from its results file."""

from __future__ import annotations

import json
import pathlib

import pytest

from shelf_env.evaluation import falls
from shelf_env.evaluation import protocol as ev

MODEL = "examples/pretrained/v1/p_s.zip"
SEED, N, RUNS = falls.VALIDATION_SEED, 4, 3


@pytest.fixture(scope="module")
def measured() -> list[falls.FallEpisode]:
    return falls.measure_cell(MODEL, N, SEED, RUNS)


def test_the_probed_run_is_the_greedy_episode_until_its_first_rescue(measured: list[falls.FallEpisode]) -> None:
    real = ev.evaluate_cell(MODEL, N, SEED, RUNS)
    for probed, episode in zip(measured, real):
        assert probed.greedy_success == episode.success
        if episode.failure in ("fell", "unstable"):  # its last action ended it invalid: the probe saw it coming
            assert probed.first_invalid == episode.actions - 1
        else:  # no greedy action of the real episode was invalid
            assert probed.first_invalid == -1
        assert 0 <= probed.fell <= probed.invalid <= probed.decisions <= 40


def test_the_summary_counts_per_action(measured: list[falls.FallEpisode]) -> None:
    s = falls.cell_summary(measured)
    assert s["decisions"] == sum(e.decisions for e in measured)
    assert s["invalid_rate"] == pytest.approx(sum(e.invalid for e in measured) / s["decisions"])
    assert s["sr"] == pytest.approx(100 * sum(e.greedy_success for e in measured) / RUNS)
    crafted = [falls.FallEpisode(0, 10, 2, 1, False, 3), falls.FallEpisode(1, 5, 0, 0, True, -1)]
    assert falls.cell_summary(crafted) == {"episodes": 2, "decisions": 15, "invalid": 2, "fell": 1,
                                           "invalid_rate": 2 / 15, "fall_rate": 1 / 15, "episodes_invalid": 1,
                                           "median_episode_rate": 0.1, "sr": 50.0}


def test_measure_resumes_from_its_file(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[str, int]] = []

    def fake_cell(policy: str, n: int, seed: int, runs: int, object_set: str = "ycb") -> list[falls.FallEpisode]:
        calls.append((policy, n))
        return [falls.FallEpisode(r, 4, 1, 1, False, 0) for r in range(runs)]

    monkeypatch.setattr(falls, "measure_cell", fake_cell)
    out = tmp_path / "falls.json"
    falls.measure(["h-d", MODEL], [3, 5], SEED, 2, out)
    assert len(calls) == 4 and len(json.loads(out.read_text())) == 4
    falls.measure(["h-d", MODEL], [3, 5, 6], SEED, 2, out)  # only the new N is measured
    assert calls[4:] == [("h-d", 6), (MODEL, 6)]
    key = falls.cell_key(MODEL, 3, SEED, 2, "ycb")
    assert key.startswith(f"{MODEL}@") and json.loads(out.read_text())[key]["fall_rate"] == 0.25


def test_bad_arguments_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert falls.main(["h-d", "--runs", "0"]) == 2
    assert "runs must be >= 1" in capsys.readouterr().err
    assert falls.main(["h-d", "--ns", "99"]) == 2
    assert "99" in capsys.readouterr().err


def test_fall_sources_records_each_decision_the_measurement_probes(measured: list[falls.FallEpisode]) -> None:
    """research.fall_sources rides on `falls.measure_episode` (its ``on_decision`` hook): one record per probed
    decision, with the same invalid and fallen counts as the measurement of the same scenes."""
    from research import fall_sources
    from shelf_env.policies import POLICIES

    env = ev.make_env(MODEL, N, "ycb")
    try:
        agent = ev.make_policy(MODEL, env, seed=ev.scene_seed(SEED, N, 10**6))
        rescue = POLICIES[falls.RESCUE](env, 0)
        for episode in measured:
            decisions = fall_sources.episode_decisions(env, agent, rescue, None, ev.scene_seed(SEED, N, episode.run))
            assert len(decisions) == episode.decisions
            assert sum(d["invalid"] for d in decisions) == episode.invalid
            assert sum(d["fell"] for d in decisions) == episode.fell
            assert all(d["risk"] is None and d["map"] in ("pick", "push_left", "push_right") for d in decisions)
    finally:
        env.close()
