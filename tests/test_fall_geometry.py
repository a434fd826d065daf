"""Named fall geometry (research.fall_geometry): the command line from a teacher dataset to the report that
learns a corridor rule, the feature channels, and the export of a fit as the product's geometry risk (the
features themselves: tests/test_fall_filter.py)."""

import json

import gymnasium as gym
import numpy as np
import pytest

from research import fall_geometry as fg
from research import fall_risk as fr
from research.tall_guard import tall_blocked_cells
from sb3_pixeldqn import PixelDoubleDQN
from shelf_env import fall_filter as ff
from shelf_env.camera.heightmap import CLASS_RGB
from shelf_env.conditions.safe_picks import Z_CARRY
from shelf_env.fall_filter import geometry_features, geometry_risk_path
from shelf_env.world.objects import YCB_KINDS
from tests.test_fall_filter import crafted, paint


def corridor_shards(folder, shards=3, episodes=8, states=5, seed=0, greedy=False, series=0, object_set="train"):
    """A teacher dataset of 20 x 30 cells (2 cm) whose picks fall exactly when a taller-than-clearance object
    stands in front of the picked one in its columns (the carry account of `shelf_env.conditions.safe_picks`).
    ``greedy``: each state's first labelled pick is the driving model's (source ``greedy``), the rest ``object``."""
    from shelf_env.privileged import dataset

    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    rows, cols = 20, 30
    centres = [(r, c) for r in range(2, 18, 4) for c in range(3, 28, 5)]
    layout = {"obs_shape": [4, rows, cols], "pixel_size": 0.02, "map_names": ["pick", "push_left", "push_right"]}
    for k in range(shards):
        eps = []
        for _ in range(episodes):
            ep = dataset.Episode()
            for t in range(states):
                obs = np.full((4, rows, cols), 255, np.uint8)
                obs[3] = 0
                chosen = [centres[i] for i in rng.permutation(len(centres))[:7]]
                tall = {rc: float(rng.choice([0.04, 0.10, 0.14])) for rc in chosen}
                for (r, c), h in tall.items():
                    paint(obs, slice(r - 1, r + 2), slice(c - 1, c + 2), CLASS_RGB[int(rng.integers(3))], h)
                for k_obj, ((r, c), h) in enumerate(tall.items()):
                    blocked = any(c2 == c and r2 > r and h + h2 > Z_CARRY for (r2, c2), h2 in tall.items())
                    source = dataset.SOURCES.index("greedy" if greedy and k_obj == 0 else "object")
                    for key, v in zip(dataset.LABEL_KEYS, (t, r * cols + c, not blocked, blocked, False,
                                                           int(not blocked), source)):
                        ep.labels[key].append(v)
                ep.obs.append(obs)
                for key, v in zip(dataset.EPISODE_STATE_KEYS, (t, 0, np.nan, 0)):
                    ep.states[key].append(v)
            eps.append(ep)
        meta = {"format": dataset.FORMAT, "dynamics_version": dataset.DYNAMICS_VERSION, "layout": layout,
                "series": series, "shard": k, "episodes": [{"num_objects": 7} for _ in range(episodes)],
                "object_set": object_set}
        dataset.save_shard(dataset.shard_path(folder, series, k), meta, eps, layout["obs_shape"])


def test_the_command_line_learns_a_corridor_rule_and_joins_the_fall_model(tmp_path, capsys):
    data = tmp_path / "data"
    corridor_shards(data)
    args = ["--data", str(data), "--val-fraction", "0.25"]
    assert fg.main(["fit", *args, "--features", str(tmp_path / "none.npz"), "--out", str(tmp_path / "r.json")]) == 2
    assert "make it with `features`" in capsys.readouterr().err and not (tmp_path / "r.json").exists()
    args += ["--max-shards", "s00:2"]
    assert fg.main(["features", *args, "--fresh", "s00:2", "--out", str(tmp_path / "f.npz")]) == 2
    assert "selects no shard" in capsys.readouterr().err and not (tmp_path / "f.npz").exists()
    assert fg.main(["features", *args, "--out", str(tmp_path / "f.npz"), "--fresh", "s00:3", "--blockers"]) == 0
    built = json.loads(capsys.readouterr().out)
    train, val = fr.load_splits(data, 0.25, max_shards="s00:2")
    test = fg.fresh_split(data, "s00:2", "s00:3")  # the third shard, every state: no fall model read it
    assert len(test.obs) == 8 * 5 and built["test_labels"] == len(test.label) == 8 * 5 * 7
    assert built["train_labels"] == len(train.label) and built["val_labels"] == len(val.label)
    with np.load(tmp_path / "f.npz") as z:
        assert np.array_equal(z["val_y"], val.label.numpy()) and z["train_x"].shape == (len(train.label), 36)
        assert np.array_equal(z["test_y"], test.label.numpy()) and z["test_x"].shape == (len(test.label), 36)
        assert len(np.unique(z["val_scene"])) == 4  # the last 4 of 16 scenes, held out
    fall_model = tmp_path / "fm.pt"
    fr.FallRiskModel(4, (4, 8, 8)).save(fall_model)  # an untrained fall model: the features carry the rule
    env = gym.make("ShelfSort-v0", pixel_size=0.02)
    PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                        widths=(4, 8, 8)), seed=0).save(tmp_path / "p.zip")
    env.close()
    out = tmp_path / "r.json"
    assert fg.main(["fit", *args, "--features", str(tmp_path / "f.npz"), "--fall-model", str(fall_model),
                    "--epochs", "40", "--checkpoint", str(tmp_path / "p.zip"), "--out", str(out), "--fresh",
                    "s00:3"]) == 0
    report = json.loads(out.read_text())
    assert report["features_set"] == "blockers" and report["test"]["labels"] == len(test.label)
    assert report["test"]["mlp"] > 0.95 and report["test"]["fcn"] == pytest.approx(fr.auc(test.label.numpy(), fr.scores(
        fr.FallRiskModel.load(fall_model), test)))
    assert set(report["test_offline"]["poolings"]) == {"mlp", "joint", "ensemble", "fcn"} - {"joint"}
    assert report["mlp"]["val_auc"] > 0.95 and report["reading"] == "features"
    assert len(report["mlp"]["history"]) == 40 and report["mlp"]["val_auc"] == max(report["mlp"]["history"])
    margin = report["features"]["carry_margin_05"]
    assert margin["sign"] == -1 and margin["val_auc"] > 0.95  # a smaller margin is riskier
    assert report["twofold"]["scenes"] == 4 and report["twofold"]["joint"] > 0.9
    assert report["twofold"]["fcn"] == pytest.approx(fr.auc(val.label.numpy(), fr.scores(
        fr.FallRiskModel.load(fall_model), val)))
    offline = report["offline"]
    assert set(offline["poolings"]) == {"mlp", "joint", "ensemble"} and offline["labels"] == len(val.label)
    assert offline["oracle"]["invalid"] <= offline["poolings"]["mlp"]["hard"][0]["invalid"] + 1e-9
    assert out.with_suffix(".models.pt").is_file()


def test_the_reading_and_the_two_fold_split():
    assert fg.reading({"mlp": {"val_auc": 0.9}, "twofold": {"joint": 0.5}}) == "features"
    assert fg.reading({"mlp": {"val_auc": 0.8}, "twofold": {"joint": 0.89}}) == "joint"
    assert fg.reading({"mlp": {"val_auc": 0.8}, "twofold": {"joint": 0.88}}) == "neither"
    assert fg.reading({"mlp": {"val_auc": 0.8}}) == "neither"
    folds = fg.scene_folds(np.array([7, 7, 3, 9, 3, 12]))
    assert folds.tolist() == [1, 1, 0, 0, 0, 1]  # scenes 3, 7, 9, 12 alternate; a scene stays in one fold
    with pytest.raises(ValueError, match="two scenes"):
        fg.twofold(np.zeros((4, 2)), np.array([0, 1, 0, 1.0]), np.array([5, 5, 5, 5]))


def test_feature_channels_hold_each_cell_s_features(tmp_path):
    obs = crafted()
    x = geometry_features(obs, np.arange(40 * 60), blockers=True)
    mean, std = x.mean(axis=0), x.std(axis=0)
    channels = fg.feature_channels(obs, mean, std)
    assert channels.shape == (36, 40, 60) and channels.dtype == np.uint8
    a = (x[7 * 60 + 12] - mean) / np.where(std > 0, std, 1)
    assert np.array_equal(channels[:, 7, 12], np.clip(np.round(a * fg.CHANNEL_STEPS + 128), 0, 255))
    flat = std == 0  # a feature that never varies sits at 128
    assert (channels[flat] == 128).all()
    with pytest.raises(ValueError, match="normalisation of 3 means"):
        fg.feature_channels(obs, mean[:3], std[:3])


def test_the_fall_model_with_feature_channels_reports_what_its_saved_weights_score(tmp_path, capsys):
    data = tmp_path / "data"
    corridor_shards(data)
    args = ["--data", str(data), "--val-fraction", "0.25", "--max-shards", "s00:2"]
    assert fg.main(["features", *args, "--blockers", "--out", str(tmp_path / "f.npz")]) == 0
    capsys.readouterr()
    out, report = tmp_path / "ch.pt", tmp_path / "ch.json"
    assert fg.main(["channels", *args, "--features", str(tmp_path / "f.npz"), "--fresh", "s00:3", "--epochs", "10",
                    "--out", str(out), "--report", str(report)]) == 0
    result = json.loads(report.read_text())
    model = fr.FallRiskModel.load(out)
    assert model.in_channels == 40 and model.info["obs_shape"] == [40, 20, 30] and len(model.info["mean"]) == 36
    assert result["best_epoch"] == int(np.argmax([h["val_auc"] for h in result["history"]])) + 1
    assert result["val_auc"] > 0.7 and result["test_auc"] > 0.7  # it learns (chance: 0.5)
    with np.load(tmp_path / "f.npz") as z:
        mean, std = z["train_x"].mean(axis=0), z["train_x"].std(axis=0)
    assert np.allclose(model.info["mean"], mean)  # the channels are normalised with the training features
    test = fg.with_channels(fg.fresh_split(data, "s00:2", "s00:3"), mean, std)
    assert result["test_auc"] == pytest.approx(fr.auc(test.label.numpy(), fr.scores(model, test)))
    assert fg.main(["channels", *args, "--features", str(tmp_path / "none.npz"), "--out", str(tmp_path / "x.pt"),
                    "--report", str(tmp_path / "x.json")]) == 2
    assert "make it with `features`" in capsys.readouterr().err and not (tmp_path / "x.pt").exists()


def test_the_geometry_risk_scores_every_object_cell_as_the_fit_did_and_filters_a_checkpoint(tmp_path, capsys):
    """An exported fit model: its risk at each labelled cell is the fit's on that label's features, 0 off
    objects; ``<zip>+geometry-filter`` plays the checkpoint under `FallFilter` with it."""
    from shelf_env import policies

    data = tmp_path / "data"
    corridor_shards(data, shards=2)
    args = ["--data", str(data), "--val-fraction", "0.25"]
    assert fg.main(["features", *args, "--blockers", "--out", str(tmp_path / "f.npz")]) == 0
    assert fg.main(["fit", *args, "--features", str(tmp_path / "f.npz"), "--epochs", "5",
                    "--out", str(tmp_path / "fit.json")]) == 0
    capsys.readouterr()
    env = gym.make("ShelfSort-v0", pixel_size=0.02)
    zip_path = tmp_path / "p.zip"
    PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                        widths=(4, 8, 8)), seed=0).save(zip_path)
    with pytest.raises(ValueError, match="no geometry risk model at .*p.geometry_risk.pt"):
        policies.check_policy(f"{zip_path}+geometry-filter")
    with pytest.raises(ValueError, match="not a checkpoint"):
        policies.check_policy("h-d+geometry-filter")
    bad = ["export", "--models", str(tmp_path / "fit.models.pt"), "--features", str(tmp_path / "f.npz"),
           "--obs-shape", "4,20,30", "--out", str(geometry_risk_path(zip_path))]
    assert fg.main([*bad, "--threshold", "1.5"]) == 2
    assert "threshold must be in (0, 1]" in capsys.readouterr().err and not geometry_risk_path(zip_path).exists()
    assert fg.main([*bad, "--threshold", "0.5", "--name", "nope"]) == 2
    assert "not 'nope'" in capsys.readouterr().err
    assert fg.main([*bad, "--threshold", "0.5"]) == 0
    risk = ff.GeometryRisk.load(geometry_risk_path(zip_path))
    assert risk.threshold == 0.5 and risk.blockers and risk.hidden == 64 and risk.info["obs_shape"] == [4, 20, 30]
    import torch as th
    fitted = ff.FeatureModel(np.zeros(36), np.ones(36), 64)
    fitted.load_state_dict(th.load(tmp_path / "fit.models.pt", weights_only=True)["mlp"])
    _, val = fr.load_splits(data, 0.25)
    with np.load(tmp_path / "f.npz") as z:
        expected = fitted.risk(z["val_x"])
    obs = val.obs[0].numpy()
    mine = val.state.numpy() == 0
    per_cell = risk.risk(obs)
    assert per_cell.shape == (20, 30)
    assert np.allclose(per_cell.reshape(-1)[val.cell.numpy()[mine]], expected[mine], atol=1e-6)
    from shelf_env.baselines.heuristics import object_blobs
    assert (per_cell[object_blobs(obs) < 0] == 0).all()  # nothing to drop where no object is
    assert policies.check_policy(f"{zip_path}+geometry-filter") == ("pick", "push")
    policy = policies.make_policy(f"{zip_path}+geometry-filter", env)
    assert isinstance(policy, ff.FallFilter) and policy.risk.threshold == 0.5
    action, _ = policy.predict(obs, action_masks=np.ones(env.action_space.n, bool))
    pick_cells = action < 20 * 30
    assert not pick_cells or per_cell.reshape(-1)[action] < 0.5  # a pick it plays is one the filter keeps
    env.close()
    # --compare: the exported risk beside a refit on the same labels; the same seed refits the same model, so
    # the two agree exactly, and the masked share is the share of labels at or over the exported threshold
    fit_args = ["fit", *args, "--features", str(tmp_path / "f.npz"), "--epochs", "5", "--out", str(tmp_path / "r.json")]
    assert fg.main([*fit_args, "--compare", str(tmp_path / "none.pt")]) == 2
    assert "--compare" in capsys.readouterr().err and not (tmp_path / "r.json").exists()
    assert fg.main([*fit_args, "--compare", str(geometry_risk_path(zip_path))]) == 0
    compared = json.loads((tmp_path / "r.json").read_text())["compare"]
    assert compared["threshold"] == 0.5 and set(compared) == {"path", "threshold", "exported", "mlp", "logistic"}
    assert compared["exported"]["val"] == compared["mlp"]["val"]
    assert compared["exported"]["val"]["masked"] == pytest.approx(float((expected >= 0.5).mean()))
    with np.load(tmp_path / "f.npz") as z:
        labels = z["val_y"].astype(bool)
    assert compared["exported"]["val"]["allowed_invalid"] == pytest.approx(float(labels[expected < 0.5].mean()))
    assert compared["exported"]["val"]["auc"] == pytest.approx(fr.auc(labels.astype(float), expected))


def test_the_two_fold_risks_do_not_depend_on_what_ran_before():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200, 3))
    y = (x[:, 0] > 0).astype(float)
    scenes = np.repeat(np.arange(10), 20)
    first = fg.twofold(x, y, scenes, hidden=8, epochs=150)
    import torch as th
    th.rand(5)  # the global generator moved on
    assert np.array_equal(fg.twofold(x, y, scenes, hidden=8, epochs=150), first)
    assert fr.auc(y, first) > 0.9  # each fold learns the rule from the other fold's scenes


def test_a_test_set_inside_the_pool_leaves_the_split(tmp_path, capsys):
    """A refit on a grown dataset keeps an older test set: ``--fresh-after`` names what the test set came after,
    so the test set may sit inside ``--max-shards``; its shards then leave the training and validation splits."""
    from shelf_env.privileged import dataset

    data = tmp_path / "data"
    corridor_shards(data, shards=4)
    sets = fg.load_sets(data, 0.25, "s00:4", fresh="s00:2", fresh_after="s00:1")
    test = fg.fresh_split(data, "s00:1", "s00:2")  # the second shard, every state
    assert sets.test is not None and th_equal(sets.test.obs, test.obs) and len(test.obs) == 8 * 5
    every = dataset.load_dataset(data)
    pool = [every[0], every[2], every[3]]  # the pool without the test shard: its split, as a fit without a test set
    train, val, _ = fr.split_teacher_shards(pool, 0.25)
    assert th_equal(sets.train.obs, train.obs) and th_equal(sets.val.obs, val.obs)
    assert len(sets.train.obs) + len(sets.val.obs) == 3 * 8 * 5
    # without --fresh-after the test set comes after --max-shards, as before; so no shard of s00:4 is fresh
    with pytest.raises(ValueError, match="selects no shard that s00:4 leaves out"):
        fg.load_sets(data, 0.25, "s00:4", fresh="s00:2")
    args = ["features", "--data", str(data), "--max-shards", "s00:4", "--val-fraction", "0.25", "--out",
            str(tmp_path / "f.npz")]
    assert fg.main([*args, "--fresh-after", "s00:1"]) == 2
    assert "--fresh-after names what a test set comes after" in capsys.readouterr().err
    assert fg.main([*args, "--fresh", "s00:4", "--fresh-after", "s00:0"]) == 2  # every shard would be the test set
    assert "selects no shard outside the test set" in capsys.readouterr().err and not (tmp_path / "f.npz").exists()
    assert fg.main([*args, "--fresh", "s00:2", "--fresh-after", "s00:1"]) == 0
    built = json.loads(capsys.readouterr().out)
    assert built["test_labels"] == len(test.label) and built["train_labels"] == len(train.label)


def test_an_extra_folder_joins_the_pool_as_a_series_of_its_own(tmp_path, capsys):
    """``--extra-data``: every shard of another folder (another object set's series) joins the pool and gives its
    own last scenes to the validation split; a shard name two folders share, or an empty folder, is refused."""
    from shelf_env.privileged import dataset

    data, wide = tmp_path / "data", tmp_path / "wide"
    corridor_shards(data, shards=2)
    corridor_shards(wide, shards=1, seed=1, series=92, object_set="train-wide")
    sets = fg.load_sets(data, 0.25, None, extra=[wide])
    pool = dataset.load_dataset(data) + dataset.load_dataset(wide)
    train, val, _ = fr.split_teacher_shards(pool, 0.25)
    assert th_equal(sets.train.obs, train.obs) and th_equal(sets.val.obs, val.obs)
    # 16 scenes of series 0 give 4 to validation, the extra series' 8 give 2: each series apart
    assert len(sets.val.obs) == (4 + 2) * 5 and len(sets.train.obs) == (12 + 6) * 5
    alone = fg.load_sets(data, 0.25, None)
    assert len(alone.val.obs) == 4 * 5 and th_equal(sets.val.obs[:20], alone.val.obs)
    clash = tmp_path / "clash"
    corridor_shards(clash, shards=1, seed=2)  # s00_00000 again
    with pytest.raises(ValueError, match="shard s00_00000.npz is also in"):
        fg.load_sets(data, 0.25, None, extra=[clash])
    (tmp_path / "empty").mkdir()
    args = ["features", "--data", str(data), "--val-fraction", "0.25", "--out", str(tmp_path / "f.npz")]
    assert fg.main([*args, "--extra-data", str(tmp_path / "empty")]) == 2
    assert "no dataset shards" in capsys.readouterr().err and not (tmp_path / "f.npz").exists()
    assert fg.main([*args, "--extra-data", str(wide)]) == 0
    assert json.loads(capsys.readouterr().out)["val_labels"] == len(val.label)


def th_equal(a, b) -> bool:
    return a.shape == b.shape and bool((a == b).all())


def test_the_greedy_report_reads_the_driving_policy_s_picks_in_the_validation_split(tmp_path, capsys):
    """`greedy_report`: an exported risk on the greedy picks of a series' validation states, and on the other
    picks of the same states; its AUC, bands and masked shares are the risk's on exactly those labels."""
    data = tmp_path / "data"
    corridor_shards(data, shards=2, greedy=True)
    args = ["--data", str(data), "--val-fraction", "0.25"]
    assert fg.main(["features", *args, "--blockers", "--out", str(tmp_path / "f.npz")]) == 0
    assert fg.main(["fit", *args, "--features", str(tmp_path / "f.npz"), "--epochs", "5",
                    "--out", str(tmp_path / "fit.json")]) == 0
    risk_path = tmp_path / "r.geometry_risk.pt"
    assert fg.main(["export", "--models", str(tmp_path / "fit.models.pt"), "--features", str(tmp_path / "f.npz"),
                    "--threshold", "0.3", "--obs-shape", "4,20,30", "--out", str(risk_path)]) == 0
    capsys.readouterr()
    report = fg.greedy_report(data, 0.25, None, None, None, "s00", {"a": risk_path})
    _, val = fr.load_splits(data, 0.25)
    assert report["states"] == len(val.obs) == 4 * 5  # the last 4 of 16 scenes, 5 states each
    greedy, others = report["greedy"], report["others"]
    assert greedy["picks"] == 4 * 5 and others["picks"] == 4 * 5 * 6
    assert greedy["by_n"] == {"3-6": {"picks": 0, "invalid": 0}, "7-10": {"picks": 20, "invalid": int(
        val.label.numpy()[np.r_[True, np.diff(val.state.numpy()) != 0]].sum())}, "11-14": {"picks": 0, "invalid": 0}}
    assert greedy["picks"] + others["picks"] == len(val.label)
    # the greedy picks are each state's first label: recompute the risk's numbers on exactly those
    first = np.r_[True, np.diff(val.state.numpy()) != 0]
    y = val.label.numpy()[first].astype(bool)
    risk = ff.GeometryRisk.load(risk_path)
    greedy_split = fr.Split(val.obs, val.state[first], val.cell[first], val.label[first])
    r = risk.model.risk(fg.split_features(greedy_split, True))
    assert greedy["invalid"] == pytest.approx(y.mean())
    assert 0 < y.sum() < len(y) and greedy["a"]["auc"] == pytest.approx(fr.auc(y.astype(float), r))
    bands = greedy["a"]["bands"]
    assert sum(b["picks"] for b in bands) == len(y) and sum(b["invalid"] for b in bands) == y.sum()
    assert greedy["a"]["bands"][-1]["picks"] == int((r >= 0.1).sum())  # the last band: at or over 0.1
    assert greedy["a"]["masked_at_threshold"] == pytest.approx((r >= 0.3).mean())
    # by the picked object's observed height: the crafted objects are 4, 10 and 14 cm tall
    height = fg.split_features(greedy_split, True)[:, ff.FEATURES.index("object_max_height")]
    by_height = greedy["by_height"]
    assert list(by_height) == ["<6", "6-9", "9-12", ">=12"] and by_height["6-9"] == {"picks": 0, "invalid": 0}
    assert by_height[">=12"] == {"picks": int((height >= 0.12).sum()), "invalid": int(y[height >= 0.12].sum())}
    assert sum(v["picks"] for v in by_height.values()) == len(y) and sum(
        v["invalid"] for v in by_height.values()) == y.sum() and by_height["<6"]["picks"] > 0
    with pytest.raises(ValueError, match="no shard of series 's07'"):
        fg.greedy_report(data, 0.25, None, None, None, "s07", {"a": risk_path})
    with pytest.raises(ValueError, match="source must be one of"):
        fr.teacher_split([], np.zeros(0, np.int64), source="teachr")
    bad = ["greedy", *args, "--series", "s00", "--out", str(tmp_path / "g.json")]
    assert fg.main([*bad, "--risk", str(risk_path)]) == 2 and "NAME=PATH" in capsys.readouterr().err
    assert fg.main([*bad, "--risk", "a=nope.pt"]) == 2 and "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "g.json").exists()
    assert fg.main([*bad, "--risk", f"a={risk_path}"]) == 0
    assert json.loads((tmp_path / "g.json").read_text()) == json.loads(json.dumps(report))
    # --all-states: every state of the series (a probe set), not the validation split
    every = fg.greedy_report(data, 0.25, None, None, None, "s00", {"a": risk_path}, all_states=True)
    assert every["states"] == 2 * 8 * 5 and every["greedy"]["picks"] == 2 * 8 * 5 and every["object_sets"] == ["train"]
    listed = fg.greedy_report(data, 0.25, None, None, None, "s07, s00", {"a": risk_path}, all_states=True)
    assert listed["series"] == "s07, s00" and {**listed, "series": "s00"} == every  # a list of series: any of them


def test_a_probe_of_unseen_objects_never_shares_a_folder_with_training_objects(tmp_path, capsys):
    data = tmp_path / "data"
    corridor_shards(data, shards=1)
    model = "examples/pretrained/p_s.zip"
    with pytest.raises(ValueError, match=r"holds shards of object set\(s\) \['train'\]"):
        fg.probe(data, 0.1, model)
    with pytest.raises(ValueError, match="the dataset collects 'train'"):
        fg.probe(tmp_path / "probe", 0.1, model, object_set="train")
    assert fg.main(["probe", "--out", str(tmp_path / "probe"), "--hours", "0", "--model", model]) == 2
    assert "hours must be > 0" in capsys.readouterr().err  # the collector's own check
    assert fg.main(["probe", "--out", str(tmp_path / "probe"), "--hours", "1e-9", "--model", model]) == 0
    assert json.loads(capsys.readouterr().out) == {"shards_written": 0} and (tmp_path / "probe").is_dir()
    assert fg.main(["probe", "--out", str(data), "--hours", "1", "--model", model]) == 2
    assert "a ycb probe goes in a folder of its own" in capsys.readouterr().err


def test_a_replay_names_the_picked_object_and_what_left_the_cabinet():
    """`picked_object` is the object a pick moves, and `_step_in_copy` names the object a carry dragged out: the
    crafted drag of tests/test_closed_loop.py (a tall box picked from behind a light one near the opening)."""
    from shelf_env.world.objects import ObjectSpec
    from tests.test_lookahead import DRAG_REGIONS

    env = gym.make("ShelfSort-v0", num_objects=2).unwrapped
    try:
        scene = [(ObjectSpec("back_box", "box", (0.05, 0.05, 0.14), 0.3), 0, 0.30, 0.05, 0.0),
                 (ObjectSpec("front_box", "box", (0.05, 0.05, 0.10), 0.15), 1, 0.06, 0.05, 0.0)]
        env.set_scene(scene, DRAG_REGIONS)
        back, front = (o.uid for o in env.world.objects)
        pick_back = env.codec.action_at("pick", 0.30, 0.05)
        pick_front = env.codec.action_at("pick", 0.06, 0.05)
        assert env.action_masks()[pick_back] and env.action_masks()[pick_front]
        assert fg.picked_object(env, pick_back) == (back, "back_box")
        assert fg.picked_object(env, pick_front) == (front, "front_box")
        free = env.codec.action_at("pick", 0.20, -0.25)
        assert fg.picked_object(env, free) == (-1, "none")  # no object under that cell
        with pytest.raises(ValueError, match="not a pick"):
            fg.picked_object(env, env.codec.action_at("push_left", 0.30, 0.05))
        dragged = fg._step_in_copy(env, pick_back)
        assert dragged["fell"] and dragged["left_uids"] == [front] and dragged["left"] == ["front_box"]
        assert len(env.world.objects) == 2  # the copy stepped, not the env
        before = env.world.positions()
        env.step(pick_back)  # the real step drags the same box out
        assert [o.uid for o in env.world.objects] == [back] and not np.allclose(env.world.positions(), before[:1])
    finally:
        env.close()


def test_the_kinds_report_tallies_every_pick_of_a_replayed_shard_by_the_object_under_it(tmp_path, capsys):
    """`kinds_report` on a shard collected here: every state replays bit for bit, every pick label is counted
    once under the kind of the object its replayed cell shows, and the excess and binomial tail follow the rate."""
    from shelf_env.privileged import dataset

    data = tmp_path / "probe"
    assert dataset.collect(data, hours=1.0, ns=(3,), model_path="examples/pretrained/p_s.zip", episodes_per_shard=2,
                           max_shards=1, explore=1.0, max_probes=4, object_set="ycb") == 1
    report = fg.kinds_report(data, 0.2, None, None, None, "s00", all_states=True, rate=0.1)
    (shard,) = dataset.load_dataset(data)
    a = shard.arrays
    assert report["states"] == report["replayed"] == shard.num_states and report["mismatched"] == 0
    pick = a["label_action"] // (a["obs"].shape[-1] * a["obs"].shape[-2]) == 0
    greedy = a["label_source"] == dataset.SOURCES.index("greedy")
    kinds = report["kinds"]
    assert set(kinds) <= set(YCB_KINDS)  # every pick cell showed an object
    assert sum(k["greedy"]["picks"] for k in kinds.values()) == report["greedy"]["picks"] == (pick & greedy).sum()
    assert sum(k["greedy"]["invalid"] for k in kinds.values()) == (pick & greedy & ~a["label_valid"]).sum()
    others = {(int(s), int(act)) for s, act, g in zip(a["label_state"][pick], a["label_action"][pick], greedy[pick])
              if not g} - {(int(s), int(act)) for s, act in zip(a["label_state"][pick & greedy],
                                                                a["label_action"][pick & greedy])}
    assert sum(k["others"]["picks"] for k in kinds.values()) == len(others) > 0
    # each state is counted once for each kind in its scene: 3 objects of 1 to 3 kinds
    assert shard.num_states <= sum(k["states"] for k in kinds.values()) <= 3 * shard.num_states
    for k in kinds.values():
        g = k["greedy"]
        assert k["excess"] == pytest.approx(g["invalid"] - 0.1 * g["picks"])
        assert k["p_above_rate"] == pytest.approx(fg.binomial_tail(g["invalid"], g["picks"], 0.1))
    assert len(report["invalid_greedy"]) == report["greedy"]["invalid"]
    assert fg.binomial_tail(0, 5, 0.3) == pytest.approx(1.0)
    assert fg.binomial_tail(2, 2, 0.3) == pytest.approx(0.09)
    assert fg.binomial_tail(1, 3, 0.5) == pytest.approx(7 / 8)
    out = tmp_path / "kinds.json"
    assert fg.main(["kinds", "--data", str(data), "--series", "s00", "--all-states", "--rate", "0.1",
                    "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == json.loads(json.dumps(report))
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["mismatched"] == 0  # after the collector's lines
    assert fg.main(["kinds", "--data", str(data), "--series", "s00", "--rate", "1.5", "--out",
                    str(tmp_path / "bad.json")]) == 2
    assert "need 0 < rate < 1" in capsys.readouterr().err and not (tmp_path / "bad.json").exists()


def test_the_carry_view_reads_the_camera_s_clear_carries_by_what_each_greedy_pick_did(tmp_path, capsys):
    """`carry_view` on the corridor shards, whose picks fall exactly when a taller-than-clearance object stands in
    front of the picked one: every valid greedy pick's carry looks clear to the camera and no invalid one's does; the
    outcome groups come from the kinds report's records, and a report with unreplayed states is refused."""
    from shelf_env.privileged import dataset

    data = tmp_path / "data"
    corridor_shards(data, shards=1, episodes=4, greedy=True)
    (shard,) = dataset.load_dataset(data)
    a = shard.arrays
    greedy = np.flatnonzero(a["label_source"] == dataset.SOURCES.index("greedy"))
    invalid = [int(a["label_state"][k]) for k in greedy if not a["label_valid"][k]]
    assert 0 < len(invalid) < len(greedy)
    records = [{"shard": shard.path.name, "state": s, "uid": 7, "left_uids": [7, 9] if i % 2 else [7],
                "picked_left": True} for i, s in enumerate(invalid)]
    kinds = {"all_states": True, "mismatched": 0, "invalid_greedy": records}
    groups = fg.carry_view(data, "s00", kinds)["groups"]
    # valid picks: clear unless the pair of heights sits within carry_clear's 5 mm tolerance of the clearance
    # (4 + 14 cm), which the crafted rule lets through; the cells read are the labels' own
    from shelf_env.baselines.heuristics import ObservationView
    from shelf_env.camera.heightmap import observed_height
    from shelf_env.conditions.safe_picks import carry_clear

    def clear(k):
        obs = a["obs"][a["label_state"][k]]
        row, col = divmod(int(a["label_action"][k]) % (20 * 30), 30)
        return bool(carry_clear(ObservationView.from_observation(obs, 0).blob, observed_height(obs), 0.02)[row, col])

    valid = [k for k in greedy if a["label_valid"][k]]
    def tall(ks):
        return sum(bool(tall_blocked_cells(a["obs"][a["label_state"][k]])[divmod(int(a["label_action"][k]) % 600, 30)])
                   for k in ks)

    assert groups["valid"] == {"picks": len(valid), "clear": sum(clear(k) for k in valid), "tall_blocked": tall(valid)}
    assert groups["valid"]["clear"] >= 0.7 * len(valid)
    # the crafted objects are 4, 10 and 14 cm tall: an invalid pick is blocked by a 14 cm one (over 12 cm) or two
    # 10 cm ones, and the 14 cm blockers are among them
    bad = [k for k in greedy if not a["label_valid"][k]]
    assert groups["bystander"] == {"picks": len(invalid) // 2, "clear": 0, "tall_blocked": tall(bad[1::2])}
    assert groups["picked"] == {"picks": len(invalid) - len(invalid) // 2, "clear": 0, "tall_blocked": tall(bad[::2])}
    assert 0 < tall(bad) < len(bad) and groups["moving"] == {"picks": 0, "clear": 0, "tall_blocked": 0}
    # with a risk: each group's mean and AUC against the valid picks (here the risk is the picked object's height)
    class Height:
        blockers = False

        @staticmethod
        def risk(x):
            return x[:, ff.FEATURES.index("object_max_height")]

    risky = fg.carry_view(data, "s00", kinds, risk=type("R", (), {"model": Height, "blockers": False})())
    assert risky["groups"] == groups

    def height(k):
        obs = a["obs"][a["label_state"][k]]
        return float(geometry_features(obs, np.array([a["label_action"][k] % 600]))[0, ff.FEATURES.index(
            "object_max_height")])

    bystander = [k for i, k in enumerate(k for k in greedy if not a["label_valid"][k]) if i % 2]
    assert risky["risk"]["valid"] == {"mean": pytest.approx(np.mean([height(k) for k in valid])),
                                      "auc_against_valid": None}
    assert risky["risk"]["bystander"]["auc_against_valid"] == pytest.approx(fr.auc(
        np.r_[np.zeros(len(valid)), np.ones(len(bystander))], np.r_[[height(k) for k in valid],
                                                                  [height(k) for k in bystander]]))
    with pytest.raises(ValueError, match="mismatched=3"):
        fg.carry_view(data, "s00", {**kinds, "mismatched": 3})
    with pytest.raises(ValueError, match=f"{shard.path.name} state {invalid[0]}: an invalid greedy pick"):
        fg.carry_view(data, "s00", {**kinds, "invalid_greedy": records[1:]})
    path = tmp_path / "kinds.json"
    path.write_text(json.dumps(kinds))
    assert fg.main(["carry", "--data", str(data), "--series", "s00", "--kinds", str(path),
                    "--out", str(tmp_path / "carry.json")]) == 0
    assert json.loads((tmp_path / "carry.json").read_text())["groups"] == groups
    capsys.readouterr()
    assert fg.main(["carry", "--data", str(data), "--series", "s00", "--kinds", str(tmp_path / "no.json"),
                    "--out", str(tmp_path / "c2.json")]) == 2
    assert "does not exist" in capsys.readouterr().err and not (tmp_path / "c2.json").exists()
