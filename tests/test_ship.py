"""shelf_env.training.ship: only finished runs and reported distillations ship, as loadable zips of their layout,
with the model card."""

import json
import shutil

import pytest

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env.cli import train
from shelf_env.training.ship import main, ship


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A tiny P+S run whose capped curriculum (N = 1 -> 2, 2 steps each) is over."""
    training = tmp_path_factory.mktemp("training")
    out = training / "p_s"
    assert train.main(["--out", str(out), "--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8",
                       "8", "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_steps=3", "--set",
                       "eval_every=1000", "--set", "max_objects=2", "--set", "max_stage_timesteps=2"]) == 0
    (out / "replay.pkl").unlink()  # as in the committed mirror
    return training


def test_a_finished_run_ships_as_a_loadable_zip_with_its_card(finished_run, tmp_path):
    out = tmp_path / "pretrained"
    assert ship(None, finished_run, out) == [out / "v1" / "p_s.zip"]  # the RL-trained P+S's place on the shelf
    model = PixelDoubleDQN.load(out / "v1" / "p_s.zip")  # no other file
    assert model.num_timesteps == 4 and model.curriculum_state["finished"] == 4
    card = (out / "README.md").read_text()
    assert card.startswith("# `v1/p_s.zip`: PixelDoubleDQN, P+S") and "`bash scripts/train_model.sh p_s`" in card
    assert "curriculum ended at env step 4" in card


def test_unfinished_unknown_or_mismatched_runs_are_refused_and_nothing_is_written(finished_run, tmp_path, capsys):
    out = tmp_path / "pretrained"
    # an unfinished run
    unfinished = tmp_path / "training"
    shutil.copytree(finished_run / "p_s", unfinished / "p_s")
    progress = json.loads((unfinished / "p_s" / "progress.json").read_text())
    progress["curriculum"]["finished"] = None
    (unfinished / "p_s" / "progress.json").write_text(json.dumps(progress))
    with pytest.raises(ValueError, match="'p_s' run in .* is not over"):
        ship(["p_s"], unfinished, out)
    assert ship(None, unfinished, out) == [] and not out.exists()  # by default only finished runs ship
    # a P+S checkpoint in the S run's place: the layout check names it
    shutil.copytree(finished_run / "p_s", unfinished / "s")
    with pytest.raises(ValueError, match=r"has the maps .* not those of 's'"):
        ship(["s"], unfinished, out)
    # an evaluation without the model's rows
    results = tmp_path / "eval"
    results.mkdir()
    (results / "results.csv").write_text("policy,object_set,num_objects\nh-a,ycb,3\n")
    assert main(["p_s", "--training", str(finished_run), "--out", str(out), "--results", str(results)]) == 2
    assert "has no rows of ['p_s']" in capsys.readouterr().out
    assert main(["p_x", "--training", str(finished_run), "--out", str(out)]) == 2
    assert "unknown models ['p_x']" in capsys.readouterr().out
    assert not out.exists()


def distillation(finished_run, folder, name="p_s_dagger3_avg2", init="examples/pretrained/p_s.zip"):
    """A distilled model as `shelf_env.training.distill` leaves it: NAME.zip and NAME.distill.json beside it."""
    folder.mkdir()
    zip_path = folder / f"{name}.zip"
    shutil.copy(finished_run / "p_s" / "model.zip", zip_path)
    val = {"loss": 9.5}
    report = {"data": "data/teacher", "shards": ["s00_00000.npz", "s00_00001.npz", "s02_00000.npz"],
              "init": init, "out": f"runs/x/{name}.zip", "train_states": 1234,
              "train_labels": 20000, "val_states": 300, "epochs": 8, "augment": ["MirrorWidth"], "progress": True,
              "anchor": 1.0, "margin": 1.0, "teacher_radius": 2, "teacher_temperature": 1.0, "seed": 0,
              "average_last": 2, "averaged": {"epochs": 2, "val": val}, "seconds": 600.0,
              "history": [{"epoch": 0, "val": {"loss": 12.0}}, {"epoch": 1, "val": {"loss": 10.0}}]}
    (folder / f"{name}.distill.json").write_text(json.dumps(report))
    return zip_path


def test_a_distilled_model_ships_as_p_s_with_its_report_and_card_beside_the_runs(finished_run, tmp_path):
    zip_path = distillation(finished_run, tmp_path / "runs", init=str(tmp_path / "pretrained" / "p_s.zip"))
    results = tmp_path / "eval"
    results.mkdir()
    (results / "results.csv").write_text(
        "policy,object_set,num_objects,sr_mean,sr_std,ae_mean,mae_mean\n"
        "p_s_dagger3_avg2,ycb,3,90.0,1.0,1.2,0.9\np_s,ycb,3,80.0,2.0,1.1,0.8\n")
    out = tmp_path / "pretrained"
    assert ship(None, finished_run, out, [results], zip_path) == [out / "p_s.zip", out / "v1" / "p_s.zip"]
    assert (out / "p_s.zip").read_bytes() == zip_path.read_bytes()
    assert json.loads((out / "p_s.distill.json").read_text())["train_states"] == 1234
    card = (out / "README.md").read_text()
    assert card.startswith("# Pretrained models: `p_s.zip`, `v1/p_s.zip`") and "`p_s.zip` is the P+S to use" in card
    assert "\n## `p_s.zip`: PixelDoubleDQN, P+S (pick-and-place, push-left, push-right), distilled" in card
    assert "3 shards (s00: 2, s02: 1), 1,234 training states with 20,000 labelled actions" in card
    # it started from the P+S that was p_s.zip then, v1/p_s.zip now
    assert f"Started from `{out / 'p_s.zip'}` as it was then (now `{out / 'v1' / 'p_s.zip'}`)" in card
    assert "its report: `" + str(out / "p_s.distill.json") + "`" in card
    assert "cross-entropy on the teacher's choice (temperature 1) on its 5 x 5-cell square" in card
    assert "the mean of the last 2 epochs' weights" in card and "Validation loss 12.00 -> 9.50" in card
    # each card's table from its own label: the distilled model under its distillation's name, v1 as p_s
    assert "this model is `p_s_dagger3_avg2` there" in card and "this model is `p_s` there" in card
    assert "| ycb | 3 | 90.0 ± 1.0 | 80.0 ± 2.0 | 1.20 | 0.90 |" in card
    assert "\n## `v1/p_s.zip`: PixelDoubleDQN, P+S" in card
    # shipping a run again keeps the distilled model's card: its report is on the shelf
    ship(["p_s"], finished_run, out)
    assert "distilled" in (out / "README.md").read_text()


def test_a_distilled_model_without_its_report_or_of_another_layout_is_refused(finished_run, tmp_path, capsys):
    zip_path = distillation(finished_run, tmp_path / "runs")
    out = tmp_path / "pretrained"
    zip_path.with_name(zip_path.stem + ".distill.json").unlink()
    assert main(["--training", str(finished_run), "--out", str(out), "--distilled", str(zip_path)]) == 2
    assert "has no distillation report beside it (p_s_dagger3_avg2.distill.json)" in capsys.readouterr().out
    # a report beside something that is not a checkpoint: the load check refuses it
    zip_path.write_bytes(b"not a zip")
    zip_path.with_name(zip_path.stem + ".distill.json").write_text("{}")
    assert main(["--training", str(finished_run), "--out", str(out), "--distilled", str(zip_path)]) == 2
    assert "ship: error:" in capsys.readouterr().out
    assert not out.exists()


def test_a_new_distilled_model_moves_the_one_it_replaces_to_v2_with_its_report_and_card(finished_run, tmp_path,
                                                                                         capsys):
    out = tmp_path / "pretrained"
    first = distillation(finished_run, tmp_path / "a", init=str(out / "p_s.zip"))
    ship(None, finished_run, out, None, first)
    # the second: other bytes (another checkpoint of the same layout), started from v1 as the recipe does
    second = distillation(finished_run, tmp_path / "b", name="p_s_dagger9_avg2", init=str(out / "v1" / "p_s.zip"))
    model = PixelDoubleDQN.load(second)
    model.num_timesteps += 1
    model.save(second)
    results = tmp_path / "eval"
    results.mkdir()
    (results / "results.csv").write_text(
        "policy,object_set,num_objects,sr_mean,sr_std,ae_mean,mae_mean\n"
        "p_s_dagger9_avg2,ycb,3,95.0,1.0,1.3,0.9\np_s_dagger3_avg2,ycb,3,90.0,1.0,1.2,0.9\n"
        "p_s,ycb,3,80.0,2.0,1.1,0.8\n")
    assert ship(None, finished_run, out, [results], second)[0] == out / "p_s.zip"
    assert (out / "p_s.zip").read_bytes() == second.read_bytes()
    assert (out / "v2" / "p_s.zip").read_bytes() == first.read_bytes()  # the one it replaced, kept
    assert json.loads((out / "v2" / "p_s.distill.json").read_text())["out"].endswith("p_s_dagger3_avg2.zip")
    assert json.loads((out / "p_s.distill.json").read_text())["out"].endswith("p_s_dagger9_avg2.zip")
    card = (out / "README.md").read_text()
    assert card.startswith("# Pretrained models: `p_s.zip`, `v2/p_s.zip`, `v1/p_s.zip`")
    assert "each in `v<k>/` with its report and card (`v2/`)" in card
    assert "\n## `v2/p_s.zip`: PixelDoubleDQN, P+S (pick-and-place, push-left, push-right), distilled" in card
    assert 'PixelDoubleDQN.load("' + str(out / "v2" / "p_s.zip") + '")' in card
    # each distilled card reads its own report and rows: the first started from p_s.zip when that was v1
    assert "this model is `p_s_dagger9_avg2` there" in card and "this model is `p_s_dagger3_avg2` there" in card
    assert f"Started from `{out / 'p_s.zip'}` as it was then (now `{out / 'v1' / 'p_s.zip'}`)" in card
    assert f"Started from `{out / 'v1' / 'p_s.zip'}` and" in card
    assert "its report: `" + str(out / "v2" / "p_s.distill.json") + "`" in card
    # shipping the same bytes again moves nothing; a third model goes to v3, the newest first
    ship(None, finished_run, out, [results], second)
    assert not (out / "v3").exists()
    model.num_timesteps += 1
    model.save(second)
    ship(None, finished_run, out, None, second)
    assert json.loads((out / "v3" / "p_s.distill.json").read_text())["out"].endswith("p_s_dagger9_avg2.zip")
    assert (out / "README.md").read_text().startswith(
        "# Pretrained models: `p_s.zip`, `v3/p_s.zip`, `v2/p_s.zip`, `v1/p_s.zip`")
    # a p_s.zip without its report cannot keep its card: refused, nothing written
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(first, bare / "p_s.zip")
    assert main(["--training", str(finished_run), "--out", str(bare), "--distilled", str(second)]) == 2
    assert "p_s.zip has no distillation report beside it (p_s.distill.json)" in capsys.readouterr().out
    assert sorted(p.name for p in bare.iterdir()) == ["p_s.zip"]
    assert (bare / "p_s.zip").read_bytes() == first.read_bytes()


def geometry_risk(checkpoint, path, threshold=0.1, shape=None):
    """A `GeometryRisk` fitted (here: made) on ``checkpoint``'s observations, saved to ``path``."""
    import numpy as np

    from shelf_env.fall_filter import FeatureModel, GeometryRisk, feature_names

    n = len(feature_names(True))
    shape = shape or PixelDoubleDQN.load(checkpoint).observation_space.shape
    GeometryRisk(FeatureModel(np.zeros(n), np.ones(n), 0), True, threshold, shape).save(path)
    return path


def test_a_distilled_p_s_ships_with_its_geometry_filter_which_moves_with_it_when_replaced(finished_run, tmp_path,
                                                                                           capsys):
    out = tmp_path / "pretrained"
    first = distillation(finished_run, tmp_path / "a", init=str(out / "p_s.zip"))
    risk = geometry_risk(first, tmp_path / "r.geometry_risk.pt")
    results = tmp_path / "eval"
    results.mkdir()
    (results / "results.csv").write_text(
        "policy,object_set,num_objects,sr_mean,sr_std,ae_mean,mae_mean\n"
        "p_s_dagger3_avg2,ycb,3,90.0,1.0,1.2,0.9\ngeo+geometry-filter+loop-breaker,ycb,3,96.0,1.0,1.3,0.9\n"
        "p_s,ycb,3,80.0,2.0,1.1,0.8\np_s_dagger9_avg2,ycb,3,91.0,1.0,1.3,0.9\n")
    # refused, nothing written: no label, a label no evaluation has, a risk of other observations, no P+S to filter
    args = ["--training", str(finished_run), "--out", str(out), "--distilled", str(first), "--geometry-risk", str(risk)]
    assert main(args) == 2
    assert "needs --geometry-label: the label its evaluations gave the filtered policy (e.g. " \
        "NAME+geometry-filter+pick-guard+loop-breaker)" in capsys.readouterr().out
    assert main([*args, "--geometry-label", "geo+loop-breaker", "--results", str(results)]) == 2
    assert "'geo+loop-breaker' is not the label of a policy played under +geometry-filter and then any of " \
        "+pick-guard, +loop-breaker" in capsys.readouterr().out
    assert main([*args, "--geometry-label", "nope+geometry-filter", "--results", str(results)]) == 2
    assert "no rows of ['nope+geometry-filter']" in capsys.readouterr().out
    other = geometry_risk(first, tmp_path / "o.pt", shape=(4, 8, 8))
    assert main([*args[:-1], str(other), "--geometry-label", "geo+geometry-filter+loop-breaker"]) == 2
    assert "was fitted on observations of shape (4, 8, 8)" in capsys.readouterr().out
    assert main([*args[:4], "--geometry-risk", str(risk), "--geometry-label", "x"]) == 2
    assert "holds none (ship one with --distilled)" in capsys.readouterr().out
    assert not out.exists()
    shipped = ship(None, finished_run, out, [results], first, risk, "geo+geometry-filter+loop-breaker")
    assert shipped[-1] == out / "p_s.geometry_risk.pt" and shipped[-1].read_bytes() == risk.read_bytes()
    assert json.loads((out / "p_s.geometry_risk.json").read_text()) == {
        "source": risk.as_posix(), "command": "bash results/fall_geometry/run.sh",
        "label": "geo+geometry-filter+loop-breaker"}
    card = (out / "README.md").read_text()
    name = f"{(out / 'p_s.zip').as_posix()}+geometry-filter+loop-breaker"
    assert "`p_s.zip+geometry-filter+loop-breaker` is the P+S to use" in card
    assert "`p_s.zip` holds its Q-maps: distilled" in card and "`p_s.zip` is the P+S to use" not in card
    assert f'policy = make_policy("{name}", env)' in card and "risk is at least 0.1 masked out" in card
    assert "this policy is `geo+geometry-filter+loop-breaker` there" in card
    assert "| ycb | 3 | 96.0 ± 1.0 | 80.0 ± 2.0 | 90.0 ± 1.0 | 91.0 ± 1.0 | 1.30 | 0.90 |" in card
    # the same policy from the registry, as the card names it
    from shelf_env import policies

    assert policies.check_policy(name) == ("pick", "push")
    # shipping a run again keeps the filter and its card
    ship(["p_s"], finished_run, out, [results])
    assert "`p_s.zip+geometry-filter+loop-breaker` is the P+S to use" in (out / "README.md").read_text()
    # re-shipped under the label of the policy with the pick guard: the card names and describes that policy
    guarded = tmp_path / "eval2"
    guarded.mkdir()
    (guarded / "results.csv").write_text((results / "results.csv").read_text()
                                         + "geo+geometry-filter+pick-guard+loop-breaker,ycb,3,97.0,1.0,1.2,0.9\n")
    ship(None, finished_run, out, [guarded], None, risk, "geo+geometry-filter+pick-guard+loop-breaker")
    card = (out / "README.md").read_text()
    name = f"{(out / 'p_s.zip').as_posix()}+geometry-filter+pick-guard+loop-breaker"
    assert "`p_s.zip+geometry-filter+pick-guard+loop-breaker` is the P+S to use: the Q-maps of `p_s.zip` played " \
        "under a camera-only pick filter (`p_s.geometry_risk.pt`, `shelf_env.fall_filter`), the pick guard " \
        "(`shelf_env.pick_guard`) and the loop breaker (`sb3_pixeldqn.LoopBreaker`)." in card
    assert "## The policy to use: under the geometry pick filter, the pick guard and the loop breaker" in card
    assert f'policy = make_policy("{name}", env)' in card and "then `shelf_env.pick_guard.PickGuard`" in card
    assert "this policy is `geo+geometry-filter+pick-guard+loop-breaker` there" in card
    assert policies.check_policy(name) == ("pick", "push")
    # a new p_s.zip (other bytes, no filter) moves the filtered one to v2/ with its filter: p_s.zip is unfiltered
    second = distillation(finished_run, tmp_path / "b", name="p_s_dagger9_avg2", init=str(out / "v1" / "p_s.zip"))
    model = PixelDoubleDQN.load(second)
    model.num_timesteps += 1
    model.save(second)
    ship(None, finished_run, out, [guarded], second)
    assert (out / "v2" / "p_s.geometry_risk.pt").read_bytes() == risk.read_bytes()
    assert (out / "v2" / "p_s.geometry_risk.json").is_file()
    assert not (out / "p_s.geometry_risk.pt").exists() and not (out / "p_s.geometry_risk.json").exists()
    card = (out / "README.md").read_text()
    assert "`p_s.zip` is the P+S to use" in card and "geometry-filter+loop-breaker` is the P+S to use" not in card
    assert f'make_policy("{(out / "v2" / "p_s.zip").as_posix()}+geometry-filter+pick-guard+loop-breaker", env)' in card
    assert card.count("## The policy to use: under the geometry pick filter") == 1
