"""The §V protocol: metrics on hand-made records, identical scenes, bad input, the CLI's resume."""

import dataclasses
import hashlib
import json
import math
import os

import gymnasium as gym
import numpy as np
import pytest
from pixel_envs import FindTheSquareEnv

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env import policies
from shelf_env.cli import evaluate as evaluate_cli
from shelf_env.evaluation import protocol as ev
from shelf_env.evaluation.protocol import EpisodeRecord


def rec(seed, run, success, actions, unsorted=3, n=3, policy="h-d"):
    return EpisodeRecord(policy, "ycb", n, seed, run, success, actions, unsorted, False)


def test_metrics_on_hand_made_records():
    seed0 = [rec(0, 0, True, 3, 3), rec(0, 1, True, 4, 2), rec(0, 2, True, 6, 3), rec(0, 3, False, 40)]
    seed1 = [rec(1, 0, True, 3, 1), rec(1, 1, False, 40), rec(1, 2, False, 7), rec(1, 3, True, 6, 3)]
    m0 = ev.seed_metrics(seed0)
    assert m0["sr"] == 75.0
    assert m0["ae"] == pytest.approx((3 / 3 + 3 / 4 + 3 / 6) / 3)
    assert m0["mae"] == pytest.approx((3 / 3 + 2 / 4 + 3 / 6) / 3)
    m1 = ev.seed_metrics(seed1)
    assert m1 == {"sr": 50.0, "ae": pytest.approx((1 + 0.5) / 2), "mae": pytest.approx((1 / 3 + 3 / 6) / 2)}
    (row,) = ev.summarize(seed0 + seed1)
    assert row["sr_mean"] == pytest.approx(62.5) and row["sr_std"] == pytest.approx(12.5)
    assert row["ae_mean"] == pytest.approx((m0["ae"] + m1["ae"]) / 2)
    assert row["ae_std"] == pytest.approx(abs(m0["ae"] - m1["ae"]) / 2)
    assert row["seeds"] == 2 and row["runs"] == 8
    # no success at all: SR 0, AE and mAE undefined
    (none,) = ev.summarize([rec(0, 0, False, 40), rec(1, 0, False, 12)])
    assert none["sr_mean"] == 0.0 and math.isnan(none["ae_mean"]) and math.isnan(none["mae_mean"])


def test_paired_comparison_reads_exactly_the_same_scenes():
    # p played scenes (0,0) (0,1) (0,2); h-d all four; h-a only (0,0) (0,1) (0,3)
    records = [rec(0, 0, True, 5, policy="p"), rec(0, 1, True, 5, policy="p"), rec(0, 2, False, 40, policy="p"),
               *(rec(0, run, run != 1, 5, policy="h-d") for run in range(4)),
               rec(0, 0, False, 40, policy="h-a"), rec(0, 1, True, 5, policy="h-a"), rec(0, 3, True, 5, policy="h-a"),
               rec(0, 0, False, 40, policy="p", n=8)]
    index = ev.by_scene(records)
    assert ev.common_scenes(index, ["p", "h-d", "h-a"], 3) == [(0, 0), (0, 1)]
    assert ev.common_scenes(index, ["p", "h-d"], 3) == [(0, 0), (0, 1), (0, 2)]
    assert ev.common_scenes(index, ["p", "nobody"], 3) == []
    assert [r.run for r in ev.scene_episodes(index, "p", 3, [(0, 2), (0, 0)])] == [2, 0]
    assert ev.scene_episodes(index, "p", 3, [(0, 3)]) is None  # a scene it did not play: no count at all
    assert ev.scene_episodes(index, "p", 3, []) is None
    assert ev.paired_sr(index, "p", 3, [(0, 0), (0, 1), (0, 2)]) == pytest.approx(200 / 3)
    assert ev.paired_sr(index, "p", 8, [(0, 0)]) == 0.0  # N is part of the key
    # over (0,0) (0,1): p sorts 2/2, h-d 1/2, h-a 1/2 -> +50 over the better
    assert ev.margin_over_best(index, "p", 3, [(0, 0), (0, 1)], ["h-d", "h-a"]) == \
        {"sr": 100.0, "best": 50.0, "margin": 50.0}
    # over (0,0) (0,1) (0,2): h-a lacks (0,2), so there is no paired margin; h-d alone sorts 2/3 like p
    assert ev.margin_over_best(index, "p", 3, [(0, 0), (0, 1), (0, 2)], ["h-d", "h-a"]) is None
    assert ev.margin_over_best(index, "p", 3, [(0, 0), (0, 1), (0, 2)], ["h-d"])["margin"] == pytest.approx(0.0)
    assert ev.margin_over_best(index, "p", 3, [(0, 0)], []) is None
    # a later record of the same episode replaces the earlier one
    assert ev.by_scene([rec(0, 0, False, 40), rec(0, 0, True, 4)])[("h-d", 3)][(0, 0)].success


def test_fig12_has_one_line_per_policy_and_object_set(tmp_path):
    records = [EpisodeRecord(policy, oset, n, seed, 0, seed == 0, 5, 2, False)
               for policy in ("h-a", "h-d") for oset in ("train", "ycb") for n in (3, 4) for seed in (0, 1)]
    rows = ev.summarize(records)
    assert len(rows) == 8 and all(r["sr_mean"] == 50.0 and r["sr_std"] == 50.0 for r in rows)
    labels = ev.plot_metrics(rows, tmp_path / "fig12.png", None)
    assert labels == ["h-a (train)", "h-a (ycb)", "h-d (train)", "h-d (ycb)"]
    assert ev.plot_metrics(rows, tmp_path / "fig10.png", "ycb") == ["h-a", "h-d"]
    assert (tmp_path / "fig12.png").stat().st_size > 10_000


def test_an_s_checkpoint_is_evaluated_on_the_pick_only_env(tmp_path):
    env = gym.make("ShelfSort-v0", primitives=("pick",))
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)))
    model.save(tmp_path / "s_model.zip")
    env.close()
    records = ev.evaluate_cell(str(tmp_path / "s_model.zip"), 1, 0, 1, "train")
    (r,) = records
    assert r.policy == "s_model" and r.num_objects == 1 and 1 <= r.actions <= 40
    if r.success:
        assert r.actions < 40 and not r.fell
    # the zip's layout chose the env: the same checkpoint is refused on the P+S env
    with pytest.raises(ValueError, match="trained with primitives"):
        ev.evaluate_cell(str(tmp_path / "s_model.zip"), 1, 0, 1, "train", primitives=("pick", "push"))


def test_success_needs_fewer_than_max_actions():
    env = gym.make("ShelfSort-v0", num_objects=1, max_actions=40)
    policy = ev.make_policy("h-d", env)
    out = ev.run_episode(env, policy, ev.scene_seed(0, 1, 0))
    assert out["success"] == (out["actions"] < 40) and out["success"]
    env.close()


def test_same_scenes_for_every_policy_and_layout():
    layouts = [gym.make("ShelfSort-v0", num_objects=5, object_set="ycb", primitives=p).unwrapped
               for p in (("pick", "push"), ("pick",))]
    for run in range(2):
        seed = ev.scene_seed(1, 5, run)
        states = []
        for env in layouts:
            obs, _ = env.reset(seed=seed)
            regions = [tuple(vars(r).values()) for r in env.world.regions]
            states.append((obs, env.world.positions(), env.world.classes(), regions))
        assert np.array_equal(states[0][0], states[1][0])
        assert np.allclose(states[0][1], states[1][1]) and np.array_equal(states[0][2], states[1][2])
        assert states[0][3] == states[1][3]
    assert ev.scene_seed(1, 5, 0) != ev.scene_seed(1, 5, 1) != ev.scene_seed(0, 5, 1)
    for env in layouts:
        env.close()


def test_bad_input_is_refused_before_work(tmp_path):
    with pytest.raises(ValueError, match="neither one of"):
        ev.check_policy("h-x")
    with pytest.raises(ValueError, match="N must be in 1..14"):
        ev.check_ns([3, 15])
    s_model = PixelDoubleDQN("FCNPolicy", FindTheSquareEnv(),
                             policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)))
    s_model.save(tmp_path / "s.zip")
    assert ev.check_policy(str(tmp_path / "s.zip")) == ("pick",)
    with pytest.raises(ValueError, match=r"trained with primitives \('pick',\)"):
        ev.check_policy(str(tmp_path / "s.zip"), ("pick", "push"))
    (tmp_path / "bad.zip").write_bytes(b"nope")
    with pytest.raises(ValueError, match="not a readable"):
        ev.check_policy(str(tmp_path / "bad.zip"))
    assert evaluate_cli.main(["--policies", "h-d", "nonexistent.zip", "--out", str(tmp_path / "o"), "--runs", "1"]) == 2
    assert not (tmp_path / "o").exists()


def test_orphaned_worker_discards_its_cell(tmp_path):
    # a worker outliving a killed evaluation must not write a cell made by code that may have changed
    path = tmp_path / "cells" / "c.json"
    assert not evaluate_cli._run_cell("h-d", 1, 0, 1, "train", str(path), parent_pid=-1)
    assert not path.exists()
    assert evaluate_cli._run_cell("h-d", 1, 0, 1, "train", str(path), parent_pid=os.getppid())
    assert len(ev.load_cell(path)) == 1


def test_cli_writes_results_and_resumes(tmp_path, capsys):
    argv = ["--policies", "h-a", "--ns", "1", "--runs", "1", "--seeds", "2", "--object-sets", "train",
            "--out", str(tmp_path), "--workers", "1"]
    assert evaluate_cli.main(argv) == 0
    assert "2 to run" in capsys.readouterr().out
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["config"]["runs"] == 1 and data["config"]["complete"]
    assert data["summary"][0]["policy"] == "h-a" and data["summary"][0]["seeds"] == 2
    assert (tmp_path / "results.csv").exists() and (tmp_path / "sr_ae_mae_train.png").stat().st_size > 10_000
    assert evaluate_cli.main(argv) == 0
    out = capsys.readouterr().out
    assert "2 already on disk, 0 to run" in out and "machines" not in out
    # every episode names the machine that played it; results.json counts them
    assert data["machines"] == {ev.machine_label(): 2} and "pybullet" in ev.machine_label()
    # a cell written before the field existed (or on another machine): counted, and the CLI says so
    cell = next((tmp_path / "cells").glob("*seed1*.json"))
    old = [{k: v for k, v in r.items() if k != "machine"} for r in json.loads(cell.read_text())]
    cell.write_text(json.dumps(old))
    assert ev.load_cell(cell)[0].machine == ""
    assert evaluate_cli.main([*argv, "--summarize-only"]) == 0
    assert "these episodes were played on 2 machines" in capsys.readouterr().out
    assert json.loads((tmp_path / "results.json").read_text())["machines"] == {ev.machine_label(): 1,
                                                                             "unrecorded": 1}


def test_first_seed_plays_other_scenes(tmp_path, capsys):
    """--first-seed F plays seeds F..F+S-1 (validation scenes), the same episodes a held-out cell of seed F is."""
    out = tmp_path / "val"
    argv = ["--policies", "h-a", "--ns", "1", "--runs", "1", "--seeds", "1", "--object-sets", "train",
            "--workers", "1"]
    assert evaluate_cli.main([*argv, "--first-seed", "2000", "--out", str(out)]) == 0
    assert [p.name for p in (out / "cells").glob("*.json")] == ["h-a__train__N01__seed2000__runs1.json"]
    record = ev.load_cell(out / "cells" / "h-a__train__N01__seed2000__runs1.json")[0]
    assert record.seed == 2000 and record == ev.evaluate_cell("h-a", 1, 2000, 1, "train")[0]
    data = json.loads((out / "results.json").read_text())
    assert data["config"]["first_seed"] == 2000 and data["config"]["complete"]
    assert evaluate_cli.main([*argv, "--first-seed", "-1", "--out", str(tmp_path / "bad")]) == 2
    assert "--first-seed must be >= 0, got -1" in capsys.readouterr().err and not (tmp_path / "bad").exists()


def test_a_label_stands_for_one_checkpoint_file(tmp_path, capsys):
    """Cells are named by the checkpoint's stem: another file of that name (a retrained model shipped
    again) is refused in a folder holding the first one's cells, instead of reusing them; two
    checkpoints with one stem in one command are refused too."""
    env = gym.make("ShelfSort-v0", primitives=("pick",))
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0)], widths=(4, 8, 8)), seed=0)
    first, other = tmp_path / "a" / "s.zip", tmp_path / "b" / "s.zip"
    model.save(first)
    next(model.policy.parameters()).data += 1.0  # another model under the same file name
    model.save(other)
    env.close()
    out = tmp_path / "eval"
    grid = ["--ns", "1", "--runs", "1", "--seeds", "1", "--object-sets", "train", "--workers", "1", "--out", str(out)]
    assert evaluate_cli.main(["--policies", str(first), *grid]) == 0
    digest = hashlib.sha256(first.read_bytes()).hexdigest()
    assert (out / "cells" / "s.sha256").read_text().strip() == digest
    capsys.readouterr()
    assert evaluate_cli.main(["--policies", str(first), *grid]) == 0  # the same file resumes
    assert "1 already on disk, 0 to run" in capsys.readouterr().out
    assert evaluate_cli.main(["--policies", str(other), *grid]) == 2
    err = capsys.readouterr().err
    assert "holds cells of another 's' checkpoint" in err and "use another --out" in err
    assert evaluate_cli.main(["--policies", str(first), str(other), *grid, "--out", str(tmp_path / "x")]) == 2
    assert "share the label 's'" in capsys.readouterr().err
    # LABEL=PATH names each file's cells: both in one folder, each fingerprinted under its own label
    both = tmp_path / "both"
    assert evaluate_cli.main(["--policies", f"one={first}", f"two={other}+loop-breaker", *grid[:-1], str(both)]) == 0
    assert sorted(p.name for p in (both / "cells").iterdir()) == [
        "one.sha256", "one__train__N01__seed0__runs1.json", "two+loop-breaker.sha256",
        "two+loop-breaker__train__N01__seed0__runs1.json"]
    assert (both / "cells" / "one.sha256").read_text().strip() == digest
    assert [r["policy"] for r in json.loads((both / "results.json").read_text())["summary"]] == ["one",
                                                                                               "two+loop-breaker"]
    assert evaluate_cli.main(["--policies", "a=h-d", "a=h-a", *grid[:-1], str(tmp_path / "y")]) == 2
    assert "policies a=h-d and a=h-a share the label 'a'" in capsys.readouterr().err
    assert evaluate_cli.main(["--policies", "a b=h-d", *grid[:-1], str(tmp_path / "y")]) == 2
    assert "LABEL=POLICY needs a label" in capsys.readouterr().err and not (tmp_path / "y").exists()
    with pytest.raises(ValueError, match="another 's' checkpoint"):
        ev.cached_cell(out, str(other), 1, 0, 1, "train")
    assert len(list((out / "cells").glob("*.json"))) == 1  # nothing written for the refused file
    # a fresh clone holds the committed cells, not the checkpoint: --summarize-only summarizes them, says so,
    # and a run that would play episodes still refuses the missing file
    moved = tmp_path / "elsewhere.zip"
    first.rename(moved)
    capsys.readouterr()
    assert evaluate_cli.main(["--policies", str(first), "h-d", *grid, "--summarize-only"]) == 0
    printed = capsys.readouterr().out
    assert "1 checkpoint(s) not on this machine" in printed and str(first) in printed
    summary = json.loads((out / "results.json").read_text())["summary"]
    assert [row["policy"] for row in summary] == ["s"] and summary[0]["runs"] == 1  # h-d has no cell: not summarized
    assert evaluate_cli.main(["--policies", str(first), *grid]) == 2
    assert "nor an existing checkpoint file" in capsys.readouterr().err


def test_reuse_cells_copies_the_same_episodes_from_another_folder(tmp_path, capsys):
    grid = ["--policies", "h-d", "--ns", "1", "--runs", "1", "--seeds", "1", "--workers", "1"]
    first, second = tmp_path / "first", tmp_path / "second"
    assert evaluate_cli.main([*grid, "--object-sets", "ycb", "--out", str(first)]) == 0
    capsys.readouterr()
    assert evaluate_cli.main([*grid, "--object-sets", "train", "ycb", "--out", str(second),
                              "--reuse-cells", str(first)]) == 0
    out = capsys.readouterr().out
    assert "2 cells, 0 already on disk, 2 to run" in out and f"1 cells copied from {first}, 1 to run" in out
    name = ev.cell_path(first, "h-d", "ycb", 1, 0, 1).name
    assert (second / "cells" / name).read_bytes() == (first / "cells" / name).read_bytes()
    assert ev.cell_path(second, "h-d", "train", 1, 0, 1).exists()  # the rest was run
    # a folder made under other conditions holds other episodes: refused before any work
    (first / "conditions.json").write_text('{"closed_loop": true}')
    third = tmp_path / "third"
    assert evaluate_cli.main([*grid, "--out", str(third), "--reuse-cells", str(first)]) == 2
    assert "holds cells evaluated under conditions {'closed_loop': True}, not none" in capsys.readouterr().err
    assert not third.exists()
    assert evaluate_cli.main([*grid, "--out", str(third), "--reuse-cells", str(tmp_path / "nowhere")]) == 2
    assert "has no cells/ folder" in capsys.readouterr().err


def test_failure_categories_from_the_trace():
    c = ev.classify_failure
    assert c(True, False, True, 3, 0, 1, False) == ""
    assert c(False, True, True, 3, 0, 1, False) == "fell"
    assert c(False, False, True, 3, 0, 1, False) == "unstable"
    assert c(False, False, False, 40, 0, 1, True) == "wrong_class"
    assert c(False, False, False, 40, 20, 1, False) == "loop"
    assert c(False, False, False, 40, 2, ev.LOOP_REPEAT, False) == "loop"
    assert c(False, False, False, 40, 19, 4, False) == "timeout"


def test_run_episode_reports_a_looping_policy_as_a_loop():
    class SameAction:
        def predict(self, obs, deterministic=True):
            return np.array(0), None  # a pick in the back-left corner: empty floor, nothing changes

    env = gym.make("ShelfSort-v0", num_objects=2, max_actions=6)
    out = ev.run_episode(env, SameAction(), reset_seed=3)
    env.close()
    assert out["success"] is False and out["actions"] == 6 and out["noops"] >= 5  # (the first capture may differ)
    assert out["max_repeat"] == 6 and out["failure"] == "loop"
    record = ev.EpisodeRecord("same", "train", 2, 0, 0, **out)
    summary = ev.episode_summary([record])
    assert summary["failures"]["loop"] == 1 and sum(summary["failures"].values()) == 1
    (row,) = ev.summarize([record])
    assert row["loop_rate"] == 1.0 and row["timeout_rate"] == 0.0


def test_an_episode_records_the_counters_of_every_wrapper_in_the_chain():
    """The outermost layer's counters keep their names, a wrapped layer's are prefixed by its class, and an episode
    records each counter's increment during it (not the running total)."""

    class Counting:
        def __init__(self, policy, key):
            self.policy, self.key, self.stats = policy, key, {key: 0, "masked": 0}

        def predict(self, obs, deterministic=True):
            self.stats[self.key] += 1
            self.stats["masked"] += 2
            return self.policy.predict(obs, deterministic=deterministic)

    class InnerGuard(Counting):
        pass

    class SameAction:
        stats = "not a dict of counters: left out"

        def predict(self, obs, deterministic=True):
            return np.array(0), None

    agent = Counting(InnerGuard(SameAction(), "guarded"), "outer")
    agent.policy.stats["guarded"] = 7  # counted before this episode
    assert ev.policy_counters(agent) == {"outer": 0, "masked": 0, "inner_guard.guarded": 7, "inner_guard.masked": 0}
    env = gym.make("ShelfSort-v0", num_objects=1, max_actions=3)
    out = ev.run_episode(env, agent, reset_seed=3)
    env.close()
    assert out["policy_stats"] == {"outer": 3, "masked": 6, "inner_guard.guarded": 3, "inner_guard.masked": 6}
    assert ev.snake_case("FallFilter") == "fall_filter" and ev.snake_case("LoopBreaker") == "loop_breaker"
    looped = Counting(None, "x")
    looped.policy = looped  # a chain that comes back to itself ends
    assert ev.policy_counters(looped) == {"x": 0, "masked": 0}


def test_evaluation_under_conditions_and_one_condition_set_per_folder(tmp_path, capsys):
    grid = ["--policies", "h-d", "--ns", "1", "--runs", "2", "--seeds", "1", "--object-sets", "train",
            "--workers", "1"]
    noisy = tmp_path / "noisy"
    assert evaluate_cli.main([*grid, "--out", str(noisy), "--perception-noise", '{"dropout": 1.0}']) == 0
    assert json.loads((noisy / "conditions.json").read_text()) == {"perception_noise": {"dropout": 1.0}}
    assert json.loads((noisy / "results.json").read_text())["config"]["conditions"] == {
        "perception_noise": {"dropout": 1.0}}
    records = [r for p in (noisy / "cells").iterdir() for r in ev.load_cell(p)]
    assert all(not r.success for r in records)  # it sees nothing to pick
    capsys.readouterr()
    # the same folder under other conditions (or none) is refused in one line
    assert evaluate_cli.main([*grid, "--out", str(noisy), "--closed-loop"]) == 2
    assert "use another --out" in capsys.readouterr().err
    assert evaluate_cli.main([*grid, "--out", str(tmp_path / "x"), "--perception-noise", '{"dropout": 2}']) == 2
    assert "dropout must be a probability" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown evaluation conditions"):
        ev.check_conditions({"gravity": 1})
    assert evaluate_cli.main([*grid, "--out", str(tmp_path / "y"), "--physics", "slow"]) == 2
    assert "unknown physics 'slow'" in capsys.readouterr().err
    ref = tmp_path / "ref"
    assert evaluate_cli.main([*grid, "--out", str(ref), "--physics", "reference"]) == 0
    assert json.loads((ref / "conditions.json").read_text()) == {"physics": "reference"}


def test_closed_loop_conditions_record_every_field_of_the_watch(tmp_path, capsys):
    from shelf_env.conditions.closed_loop import DragWatch

    grid = ["--policies", "h-d", "--ns", "1", "--runs", "1", "--seeds", "1", "--object-sets", "train",
            "--workers", "1"]
    default, variant = tmp_path / "default", tmp_path / "variant"
    assert evaluate_cli.main([*grid, "--out", str(default), "--closed-loop"]) == 0
    # the watch's fields, not `true`: a later change of DragWatch's defaults cannot resume this folder
    assert json.loads((default / "conditions.json").read_text()) == {"closed_loop": dataclasses.asdict(DragWatch())}
    assert evaluate_cli.main([*grid, "--out", str(variant), "--closed-loop", '{"sustain": 2}']) == 0
    recorded = json.loads((variant / "conditions.json").read_text())["closed_loop"]
    assert recorded == {**dataclasses.asdict(DragWatch()), "sustain": 2}
    assert ev.make_env("h-d", 1, "train", conditions={"closed_loop": recorded}).unwrapped.drag_watch.sustain == 2
    capsys.readouterr()
    assert evaluate_cli.main([*grid, "--out", str(default), "--closed-loop", '{"sustain": 2}']) == 2
    assert "use another --out" in capsys.readouterr().err
    assert evaluate_cli.main([*grid, "--out", str(tmp_path / "bad"), "--closed-loop", '{"sustian": 2}']) == 2
    assert "unknown closed_loop keys ['sustian']" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
    with pytest.raises(ValueError, match="closed_loop must be true, false or a dict of DragWatch fields"):
        ev.check_conditions({"closed_loop": "yes"})
    with pytest.raises(ValueError, match="DragWatch.threshold must be a finite number >= 0, got -1"):
        ev.check_conditions({"closed_loop": {"threshold": -1}})


def test_plot_conditions_draws_curves_from_two_evaluations(tmp_path, capsys):
    from research import plot_conditions

    for level, ok in (("0", (True, True)), ("0.2", (True, False))):
        records = [ev.EpisodeRecord(p, "ycb", n, 0, run, s, 4, 2, not s) for p in ("h-a", "h-d") for n in (5, 8)
                   for run, s in enumerate(ok)]
        ev.write_results(tmp_path / level, records, {})
    out = tmp_path / "curves.png"
    plot_conditions.main(["--metric", "sr", "--x", "condition", "--ns", "5", "8", "--runs",
                          f"{tmp_path / '0'}:0", f"{tmp_path / '0.2'}:0.2", "--out", str(out)])
    printed = capsys.readouterr().out
    assert "N=5        h-a: 0 -> 100, 0.2 -> 50" in printed and out.stat().st_size > 5000
    plot_conditions.main(["--metric", "fell_rate", "--x", "n", "--runs", f"{tmp_path / '0'}:off",
                          f"{tmp_path / '0.2'}:on", "--out", str(tmp_path / "falls.png")])
    assert "h-d (on): N=5: 0.5, N=8: 0.5" in capsys.readouterr().out


def test_a_label_prefix_names_a_policys_results() -> None:
    assert ev.policy_label("mine=runs/a/model.zip+loop-breaker") == "mine+loop-breaker"
    assert ev.policy_file("mine=runs/a/model.zip+loop-breaker") == "runs/a/model.zip"
    assert ev.policy_label("runs/a/model.zip+loop-breaker") == "model+loop-breaker"  # the stem by default
    assert ev.policy_label("hd=h-d") == "hd" and ev.is_named("hd=h-d") and ev.policy_label("h-d") == "h-d"
    assert policies.split_label("runs/a=b/model.zip") == (None, "runs/a=b/model.zip")  # '=' inside a path
    assert policies.relabelled_file("m=a/b.zip+loop-breaker", "/tmp/c.zip") == "m=/tmp/c.zip+loop-breaker"
    assert policies.relabelled_file("a/my s.zip+loop-breaker", "/tmp/x/my s.zip") == "/tmp/x/my s.zip+loop-breaker"
    for bad in ("a b=x.zip", "=x.zip", "x="):
        with pytest.raises(ValueError, match="LABEL=POLICY needs a label"):
            ev.policy_label(bad)
