"""The learned fall-risk filter: labels that are what the env's step does, a resumable collection, a
model that learns a cell-wise rule and picks its threshold on held-out episodes, a filter that
masks exactly the risky picks, and its evaluation policy name ``<zip>+fall-filter``."""

import json

import gymnasium as gym
import numpy as np
import pytest
import torch as th

from research import fall_risk as fr
from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.loop_breaker import LoopBreaker
from shelf_env import policies
from shelf_env.evaluation import protocol as ev
from tests.test_fall_filter import FixedRisk


def test_each_label_is_what_stepping_that_pick_does():
    """A probe's label is the validity of the real step of that pick from that state; the probes
    leave the played episode untouched (its first observation is the reset's)."""
    env = gym.make("ShelfSort-v0", num_objects=4, object_set="train")
    try:
        rng = np.random.default_rng(3)
        data = fr.collect_episode(env, None, reset_seed=11, rng=rng, max_probes=3)
        first, _ = env.reset(seed=11)
        assert np.array_equal(data["obs"][0], first)
        obs, probes = data["obs"], data["probes"]
        assert obs.dtype == np.uint8 and obs.shape[1:] == (4, 80, 120) and probes.shape[1] == 4
        assert set(np.unique(probes[:, 3])) <= {0, 1} and probes[:, 0].max() < len(obs)
        assert np.all(np.bincount(probes[:, 0]) <= 3)  # at most max_probes per state
        codec = env.unwrapped.codec
        for _, row, col, invalid in probes[probes[:, 0] == 0]:
            env.reset(seed=11)
            _, _, terminated, _, info = env.step(codec.encode("pick", int(row), int(col)))
            assert invalid == int(terminated and not info["is_success"])
    finally:
        env.close()


def test_collection_writes_one_file_per_episode_and_resumes(tmp_path):
    out = tmp_path / "data"
    assert fr.collect(out, episodes=2, ns=(2,), model_path=None) == 2
    files = sorted(out.glob("*.npz"))
    assert [f.name for f in files] == ["shard00_ep00000.npz", "shard00_ep00001.npz"]
    with np.load(files[0]) as data:
        meta = json.loads(str(data["meta"]))
        assert meta["num_objects"] == 2 and meta["object_set"] == "train" and meta["model"] is None
        assert meta["reset_seed"] == fr.collect_seed(0, 0)
    assert fr.collect(out, episodes=3, ns=(2,), model_path=None, hours=0.0) == 0  # out of time at once
    assert fr.collect(out, episodes=2, ns=(2,), model_path=None) == 0  # nothing left to do
    assert not list(out.glob(".*partial"))
    for kwargs, word in [({"episodes": 0}, "episodes"), ({"episodes": 1, "ns": ()}, "ns"),
                         ({"episodes": 1, "explore": 1.5}, "explore")]:
        with pytest.raises(ValueError, match=word):
            fr.collect(tmp_path / "bad", model_path=None, **kwargs)
    assert not (tmp_path / "bad").exists()


def synthetic_episodes(folder, episodes=12, states=6, seed=0):
    """Episodes whose label rule is visible in the image: a pick is invalid where channel 0 is dark
    (3x3 patches around probe cells 4 apart, so no patch covers another's cell)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    centres = [(r, c) for r in range(2, 16, 4) for c in range(2, 24, 4)]
    for e in range(episodes):
        obs = np.full((states, 4, 16, 24), 255, np.uint8)
        probes = []
        for t in range(states):
            for i in rng.permutation(len(centres))[:8]:
                r, c = centres[i]
                dark = int(rng.random() < 0.3)
                obs[t, 0, r - 1:r + 2, c - 1:c + 2] = 0 if dark else 255
                probes.append((t, r, c, dark))
        np.savez_compressed(folder / f"shard00_ep{e:05d}.npz", obs=obs, probes=np.array(probes, np.int64),
                            meta=np.array("{}"))


def test_training_learns_a_cellwise_rule_and_chooses_its_threshold_on_held_out_episodes(tmp_path):
    synthetic_episodes(tmp_path / "data")
    report = fr.train_fall_risk(tmp_path / "data", tmp_path / "risk.pt", init=None, epochs=40, batch=8, lr=3e-3)
    assert report["val_states"] == 12 and report["train_states"] == 60  # 2 of 12 episodes held out
    assert report["val_auc"] > 0.85 and report["val_recall_invalid"] > 0.7 and report["val_recall_valid"] > 0.7
    model = fr.FallRiskModel.load(tmp_path / "risk.pt")
    assert model.threshold == report["threshold"] and model.info["val_auc"] == report["val_auc"]
    assert model.info["obs_shape"] == [4, 16, 24]
    obs = np.full((4, 16, 24), 255, np.uint8)
    obs[0, 5:8, 9:12] = 0
    risk = model.risk(obs)
    assert risk.shape == (16, 24) and risk[6, 10] >= model.threshold > risk[10, 2]
    assert model.risk(obs[None]).shape == (1, 16, 24)
    with pytest.raises(ValueError, match="does not exist"):
        fr.FallRiskModel.load(tmp_path / "missing.pt")
    (tmp_path / "junk.pt").write_text("not a model")
    with pytest.raises(ValueError, match="not a readable fall-risk model"):
        fr.FallRiskModel.load(tmp_path / "junk.pt")
    with pytest.raises(ValueError, match="no collected episodes"):
        fr.train_fall_risk(tmp_path, tmp_path / "x.pt")
    assert not (tmp_path / "x.pt").exists()


def synthetic_teacher_shards(folder, shards=2, episodes=6, states=6, seed=0):
    """A teacher dataset (`shelf_env.privileged.dataset` shards, series 0) with `synthetic_episodes`'s rule for
    picks (invalid where channel 0 is dark) and push labels that are all invalid at the same cells, so a
    split that let a push through would be seen in its labels and its AUC."""
    from shelf_env.privileged import dataset

    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    centres = [(r, c) for r in range(2, 16, 4) for c in range(2, 24, 4)]
    rows, cols = 20, 30  # the env's cells at pixel_size 0.02
    layout = {"obs_shape": [4, rows, cols], "pixel_size": 0.02, "map_names": ["pick", "push_left", "push_right"]}
    for k in range(shards):
        eps = []
        for _ in range(episodes):
            ep = dataset.Episode()
            for t in range(states):
                obs = np.full((4, rows, cols), 255, np.uint8)
                for i in rng.permutation(len(centres))[:8]:
                    r, c = centres[i]
                    dark = bool(rng.random() < 0.3)
                    obs[0, r - 1:r + 2, c - 1:c + 2] = 0 if dark else 255
                    for m in (0, 1):  # the pick, and a push at the same cell (never valid)
                        valid = not dark if m == 0 else False
                        for key, v in zip(dataset.LABEL_KEYS, (t, m * rows * cols + r * cols + c, valid, not valid,
                                                               False, int(valid), 2)):  # a valid pick sorts one
                            ep.labels[key].append(v)
                ep.obs.append(obs)
                for key, v in zip(dataset.EPISODE_STATE_KEYS, (t, 0, np.nan, 0)):
                    ep.states[key].append(v)
            eps.append(ep)
        meta = {"format": dataset.FORMAT, "dynamics_version": dataset.DYNAMICS_VERSION, "layout": layout,
                "series": 0, "shard": k, "episodes": [{"num_objects": 3 + e % 2} for e in range(episodes)]}
        dataset.save_shard(folder / f"s00_{k:05d}.npz", meta, eps, layout["obs_shape"])


def test_training_on_a_teacher_dataset_reads_its_pick_labels_split_by_scene(tmp_path):
    """The teacher dataset's pick labels (pushes left out), held out by scene as the distillation holds them
    out; the recall threshold flags that share of the held-out falls, `rethreshold` writes a copy with
    another threshold, and the greedy check reads the same split."""
    synthetic_teacher_shards(tmp_path / "data")
    train, val = fr.load_splits(tmp_path / "data", 0.25)
    assert len(train.obs) == 54 and len(val.obs) == 18  # 3 of 12 scenes held out (the last of series 0)
    assert len(train.label) == 54 * 8 and len(val.label) == 18 * 8  # one pick label per probed cell
    dark = train.obs[train.state, 0].flatten(1)[th.arange(len(train.cell)), train.cell] == 0
    assert th.equal(train.label.bool(), dark)  # invalid exactly where the pick was labelled invalid
    assert 0 < float(val.label.mean()) < 1
    assert int(train.state.max()) == 53 and int(val.state.max()) == 17
    first = fr.load_splits(tmp_path / "data", 0.25, max_shards="s00:1")
    assert len(first[0].obs) + len(first[1].obs) == 36  # one shard of six scenes
    fewer = fr.load_splits(tmp_path / "data", 0.25, max_states=10)
    assert th.equal(fewer[0].obs, train.obs[:10]) and th.equal(fewer[1].obs, val.obs)  # the same held-out scenes
    assert th.equal(fewer[0].label, train.label[train.state < 10])
    report = fr.train_fall_risk(tmp_path / "data", tmp_path / "bal.pt", init=None, epochs=30, batch=8, lr=3e-3,
                                val_fraction=0.25)
    assert report["val_states"] == 18 and report["train_states"] == 54 and report["val_fraction"] == 0.25
    assert report["val_auc"] > 0.85 and report["val_recall_invalid"] > 0.7 and report["val_recall_valid"] > 0.7
    strict = fr.rethreshold(tmp_path / "bal.pt", tmp_path / "data", 1.0, tmp_path / "r100.pt")
    copy = fr.FallRiskModel.load(tmp_path / "r100.pt")
    assert copy.threshold == strict["threshold"] and strict["val_recall_invalid"] == 1.0
    assert copy.info["rethresholded_from"] == str(tmp_path / "bal.pt") and copy.info["val_auc"] == report["val_auc"]
    scores = fr.scores(copy, val)
    lowest_fall = scores[val.label.numpy() == 1].min()
    assert copy.threshold <= lowest_fall < copy.threshold + 0.01  # every held-out fall flagged, no higher threshold
    assert strict["threshold"] == fr.recall_threshold(val.label.numpy(), scores, 1.0)
    env = gym.make("ShelfSort-v0", pixel_size=0.02)  # 20 x 30 cells, the synthetic layout
    PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                        widths=(4, 8, 8)), seed=0).save(tmp_path / "p.zip")
    env.close()
    check = fr.greedy_check(tmp_path / "data", copy, str(tmp_path / "p.zip"))
    assert check["val_states"] == 18 and check["probes_invalid"] == pytest.approx(float(val.label.mean()))
    assert check["auc"] == pytest.approx(fr.auc(val.label.numpy(), scores))  # the model's ranking of those labels
    policy = PixelDoubleDQN.load(tmp_path / "p.zip").policy
    q = np.array([policy.q_map_values(val.obs[int(t)].numpy())[0].reshape(-1)[int(c)]
                  for t, c in zip(val.state, val.cell)])
    assert check["q_auc"] == pytest.approx(fr.auc(val.label.numpy(), -q))  # the checkpoint's own ranking
    by = check["by_objects"]  # held out: scenes 3, 4, 5 of the second shard, with 4, 3 and 4 objects
    assert sorted(by) == [3, 4] and by[3]["labels"] == 6 * 8 and by[4]["labels"] == 12 * 8
    # a synthetic pick sorts one object exactly when it is valid
    assert check["greedy_sorted"] == pytest.approx(1 - check["greedy_invalid"])
    assert check["filtered_sorted"] == pytest.approx(1 - check["filtered_invalid"])
    sweep = {row["threshold"]: row for row in check["sweep"]}
    assert sorted(sweep) == list(fr.SWEEP)
    assert all(r["filtered_sorted"] == pytest.approx(1 - r["filtered_invalid"]) for r in sweep.values())
    flags_every_fall = [t for t in sweep if t <= lowest_fall]  # so the filtered choice never lands on a fall it could
    assert flags_every_fall and all(sweep[t]["filtered_invalid"] <= check["greedy_invalid"] for t in flags_every_fall)
    all_invalid = [bool(val.label[val.state == t].all()) for t in range(18)]
    assert check["oracle_invalid"] == pytest.approx(np.mean(all_invalid))  # invalid only where every pick is
    assert check["oracle_sorted"] == pytest.approx(1 - check["oracle_invalid"])
    # every fall flagged: the filtered choice is invalid only where no labelled pick is kept
    assert np.mean(all_invalid) <= check["filtered_invalid"] < check["greedy_invalid"]
    with pytest.raises(ValueError, match="asks for 3 shards of series s00"):
        fr.load_splits(tmp_path / "data", 0.25, max_shards="s00:3")


def test_the_recall_threshold():
    labels = np.array([0, 0, 0, 1, 1, 1, 1])
    p = np.array([0.1, 0.5, 0.7, 0.3, 0.6, 0.8, 0.9])
    assert fr.recall_threshold(labels, p, 1.0) == 0.3  # the lowest fall's score
    assert fr.recall_threshold(labels, p, 0.75) == 0.6
    assert fr.recall_threshold(labels, p, 0.5) == 0.8
    assert fr.threshold_report(labels, p, 0.6) == {"threshold": 0.6, "val_recall_invalid": 0.75,
                                                   "val_recall_valid": pytest.approx(2 / 3)}
    for bad in (0.0, 1.5):
        with pytest.raises(ValueError, match="recall must be in"):
            fr.recall_threshold(labels, p, bad)
    with pytest.raises(ValueError, match="no fall among"):
        fr.recall_threshold(np.zeros(3), p[:3], 0.9)


def test_the_auc_and_the_threshold():
    labels = np.array([0, 0, 1, 1])
    assert fr.auc(labels, np.array([0.1, 0.2, 0.8, 0.9])) == 1.0
    assert fr.auc(labels, np.array([0.9, 0.8, 0.2, 0.1])) == 0.0
    assert fr.auc(labels, np.array([0.5, 0.5, 0.5, 0.5])) == 0.5
    assert 0.2 < fr.pick_threshold(labels, np.array([0.1, 0.2, 0.8, 0.9])) <= 0.8


def test_the_evaluation_plays_a_checkpoint_under_its_fall_filter(tmp_path):
    """``PATH+fall-filter`` (and ``+loop-breaker`` after it): its own label, the model beside the
    checkpoint, refused without one or for a named policy, cells fingerprinted with the model too. The
    wrapper comes from the registry, where research.fall_risk registers it on import."""
    assert policies.WRAPPERS[fr.FALL_FILTER].files is not None
    env = gym.make("ShelfSort-v0")
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                                  widths=(4, 8, 8)), seed=0)
    model.save(tmp_path / "p.zip")
    env.close()
    zip_path = str(tmp_path / "p.zip")
    policy = zip_path + fr.FALL_FILTER + ev.LOOP_BREAKER
    assert ev.policy_wrappers(policy) == (zip_path, (fr.FALL_FILTER, ev.LOOP_BREAKER))
    assert ev.policy_wrappers(zip_path + ev.LOOP_BREAKER) == (zip_path, (ev.LOOP_BREAKER,))
    assert ev.policy_label(policy) == "p+fall-filter+loop-breaker" and ev.policy_file(policy) == zip_path
    with pytest.raises(ValueError, match="no fall-risk model at .*p.fall_risk.pt"):
        ev.check_policy(policy)
    with pytest.raises(ValueError, match="not a checkpoint"):
        ev.check_policy("h-d" + fr.FALL_FILTER)
    fr.FallRiskModel(4, (4, 8, 8), threshold=0.5).save(fr.fall_filter_path(zip_path))
    assert ev.check_policy(policy) == ("pick", "push")
    env = ev.make_env(policy, 2, "train")
    try:
        agent = ev.make_policy(policy, env)
        assert isinstance(agent, LoopBreaker) and isinstance(agent.policy, fr.FallFilter)
        wrapped = ev.run_episode(env, agent, ev.scene_seed(0, 2, 0))["policy_stats"]
        assert set(wrapped) == {"bans", "redirects", "fall_filter.masked", "fall_filter.unfiltered"}
        record = ev.run_episode(env, ev.make_policy(zip_path + fr.FALL_FILTER, env), ev.scene_seed(0, 2, 0))
        assert set(record["policy_stats"]) == {"masked", "unfiltered"}
    finally:
        env.close()
    ev.check_cell_owner(tmp_path / "out", [policy], record=True)
    fr.FallRiskModel(4, (4, 8, 8), threshold=0.9).save(fr.fall_filter_path(zip_path))  # another filter
    with pytest.raises(ValueError, match="holds cells of another"):
        ev.check_cell_owner(tmp_path / "out", [policy])


def test_a_spawned_evaluation_worker_knows_the_experiment_s_wrapper() -> None:
    """shelf-evaluate's workers import the modules that registered wrappers (research.fall_risk)."""
    assert "research.fall_risk" in policies.registering_modules()
    policies.import_modules(policies.registering_modules())


class OracleRisk:
    """Flags exactly the probed cells that were invalid (a perfect filter on the collected states)."""

    threshold = 0.5

    def __init__(self, episodes):
        self.maps = {}
        for ep in episodes:
            for t, obs in enumerate(ep["obs"]):
                risk = np.zeros(obs.shape[1:])
                probes = ep["probes"][ep["probes"][:, 0] == t]
                risk[probes[:, 1], probes[:, 2]] = probes[:, 3]
                self.maps[obs.tobytes()] = risk

    def risk(self, obs):
        return self.maps[np.asarray(obs).tobytes()]


def test_greedy_check_reads_the_models_choice_with_and_without_the_filter(tmp_path):
    """On collected episodes: an untrained model's choice among the probed picks, unfiltered and
    filtered; a filter that flags nothing changes nothing, a perfect one leaves only the states
    where every probed pick was invalid."""
    fr.collect(tmp_path / "data", episodes=3, ns=(5,), model_path=None)
    env = gym.make("ShelfSort-v0")
    PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                        widths=(4, 8, 8)), seed=0).save(tmp_path / "p.zip")
    env.close()
    episodes = fr.load_dataset(tmp_path / "data")
    val = episodes[-1:]  # 15 % of 3 episodes rounds to one
    none = fr.greedy_check(tmp_path / "data", FixedRisk(np.zeros((80, 120))), str(tmp_path / "p.zip"))
    assert none["val_states"] == len(val[0]["obs"]) and none["filtered_invalid"] == none["greedy_invalid"]
    assert none["probes_invalid"] == pytest.approx(val[0]["probes"][:, 3].mean())
    oracle = fr.greedy_check(tmp_path / "data", OracleRisk(val), str(tmp_path / "p.zip"))
    all_invalid = [bool(val[0]["probes"][val[0]["probes"][:, 0] == t, 3].all()) for t in range(len(val[0]["obs"]))]
    assert oracle["filtered_invalid"] == pytest.approx(np.mean(all_invalid))
    assert oracle["greedy_invalid"] == none["greedy_invalid"]
    assert oracle["auc"] == 1.0 and "by_objects" not in oracle  # collected episodes do not say their N here


def test_the_command_line_names_bad_input_in_one_line_and_writes_nothing(tmp_path, capsys):
    assert fr.main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "m.pt")]) == 2
    assert "no collected episodes" in capsys.readouterr().err and not (tmp_path / "m.pt").exists()
    missing = str(tmp_path / "x.zip")
    assert fr.main(["collect", "--out", str(tmp_path / "d"), "--episodes", "1", "--model", missing]) == 2
    assert "neither one of" in capsys.readouterr().err and not (tmp_path / "d").exists()
    assert fr.main(["check", "--data", str(tmp_path), "--model", str(tmp_path / "m.pt"), "--checkpoint", "p.zip"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert fr.main(["threshold", "--data", str(tmp_path), "--model", str(tmp_path / "m.pt"), "--recall", "0.9",
                    "--out", str(tmp_path / "r.pt")]) == 2
    assert "does not exist" in capsys.readouterr().err and not (tmp_path / "r.pt").exists()
    synthetic_episodes(tmp_path / "episodes", episodes=2)
    assert fr.main(["train", "--data", str(tmp_path / "episodes"), "--out", str(tmp_path / "m.pt"),
                    "--max-shards", "s00:1"]) == 2
    assert "select a teacher dataset's shards" in capsys.readouterr().err and not (tmp_path / "m.pt").exists()
    assert fr.main(["train", "--data", str(tmp_path / "episodes"), "--out", str(tmp_path / "m.pt"),
                    "--recall", "1.5"]) == 2
    assert "recall must be in (0, 1]" in capsys.readouterr().err and not (tmp_path / "m.pt").exists()


def test_coordinate_channels_start_as_the_pick_fcn_keep_the_mirror_and_survive_a_save(tmp_path):
    """With ``coords`` the model starts computing exactly the pick FCN's map (the new channels' weights are
    zero), its coordinate channels are the same for a cell and its mirror image (so the mirror augmentation
    stays exact), and a saved model loads with them."""
    env = gym.make("ShelfSort-v0", pixel_size=0.02)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                                widths=(4, 8, 8)), seed=0)
    obs, _ = env.reset(seed=3)
    env.close()
    fcn = model.policy.q_net.fcns["pick"]
    risk = fr.FallRiskModel(4, widths=(4, 8, 8), coords=True)
    risk.start_from(fcn)
    x = th.as_tensor(obs[None])
    with th.no_grad():
        assert th.allclose(risk(x), fcn(x.float() / 255.0), atol=1e-6)
        th.nn.init.normal_(risk.fcn.stem.weight)  # the coordinates now count
        assert not th.allclose(risk(x), fcn(x.float() / 255.0), atol=1e-3)
    grid = fr.coordinate_grid(20, 30)
    assert th.equal(grid, th.flip(grid, dims=(-1,))) and grid.shape == (2, 20, 30)
    assert grid[0, 0, 0] == 0 and grid[0, 19, 0] == 1 and grid[1, 0, 0] == grid[1, 0, 29] == pytest.approx(29 / 30)
    assert grid[1, 0, 14] == grid[1, 0, 15] == pytest.approx(1 / 30)
    risk.save(tmp_path / "c.pt")
    back = fr.FallRiskModel.load(tmp_path / "c.pt")
    assert back.coords and np.allclose(back.risk(obs), risk.risk(obs), atol=1e-6)
    plain = fr.FallRiskModel(4, widths=(4, 8, 8))
    plain.save(tmp_path / "p.pt")
    assert not fr.FallRiskModel.load(tmp_path / "p.pt").coords


def test_object_pooling_spreads_the_risk_over_each_object():
    """Each object (a blob of one class colour; touching objects of two classes stay two) takes its mean or
    maximum risk; cells on no object keep theirs; ``cell`` changes nothing; an unknown pooling is refused."""
    from shelf_env.camera.heightmap import CLASS_RGB

    obs = np.full((4, 10, 12), 255, np.uint8)
    blobs = {0: (slice(1, 3), slice(1, 4)), 1: (slice(1, 3), slice(4, 6)), 2: (slice(6, 9), slice(8, 11))}
    for colour, where in zip((CLASS_RGB[0], CLASS_RGB[1], CLASS_RGB[0]), blobs.values()):
        obs[:3][(slice(None), *where)] = np.asarray(colour, np.uint8)[:, None, None]
    risk = np.random.default_rng(0).random((10, 12))
    mean, high = fr.object_pooled(risk, obs, "mean"), fr.object_pooled(risk, obs, "max")
    on = np.zeros((10, 12), bool)
    for where in blobs.values():
        on[where] = True
        assert np.allclose(mean[where], risk[where].mean()) and np.allclose(high[where], risk[where].max())
    assert np.array_equal(mean[~on], risk[~on]) and np.array_equal(high[~on], risk[~on])
    assert fr.object_pooled(risk, obs, "cell") is risk
    assert np.array_equal(fr.object_pooled(risk, np.full_like(obs, 255), "mean"), risk)  # no object at all
    with pytest.raises(ValueError, match="pooling must be one of"):
        fr.object_pooled(risk, obs, "median")


def test_choose_masks_or_penalises_the_risk():
    groups = [np.array([0, 1, 2]), np.array([3, 4])]
    values = np.array([3.0, 2.0, 1.0, 5.0, 4.9])
    risk = np.array([0.9, 0.5, 0.1, 0.2, 0.0])
    assert fr.choose(groups, values, risk).tolist() == [0, 3]  # the highest value
    assert fr.choose(groups, values, risk, threshold=0.15).tolist() == [2, 4]
    assert fr.choose(groups, values, risk, threshold=0.05).tolist() == [0, 4]  # nothing kept: unmasked
    assert fr.choose(groups, values, risk, penalty=1.0).tolist() == [0, 4]  # 3 - 0.9 > 2 - 0.5; 4.9 > 5 - 0.2
    assert fr.choose(groups, values, risk, penalty=3.0).tolist() == [2, 4]  # 1 - 0.3 > 2 - 1.5 > 3 - 2.7


def test_the_penalty_check_and_its_candidate(tmp_path):
    """On a synthetic teacher dataset with a risk that flags exactly the invalid picks (dark cells): every
    hard threshold and a large enough penalty leave only the states where every labelled pick was invalid;
    a risk of zero changes nothing; the candidate is the plan's rule on the result."""
    synthetic_teacher_shards(tmp_path / "data")
    env = gym.make("ShelfSort-v0", pixel_size=0.02)
    PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0), ("push", 0), ("push", 180)],
                                                        widths=(4, 8, 8)), seed=0).save(tmp_path / "p.zip")
    env.close()

    class Dark(FixedRisk):
        info = {"val_fraction": 0.25}

        def risk(self, obs):
            return (np.asarray(obs)[0] == 0).astype(float)

    _, val = fr.load_splits(tmp_path / "data", 0.25)
    result = fr.penalty_check(tmp_path / "data", Dark(None), str(tmp_path / "p.zip"), penalties=(1e-9, 1e9))
    all_invalid = np.mean([bool(val.label[val.state == t].all()) for t in range(18)])
    assert result["val_states"] == 18 and result["labels"] == len(val.label) and result["q_sigma"] > 0
    assert result["oracle"]["invalid"] == pytest.approx(all_invalid)
    assert list(result["poolings"]) == list(fr.POOLINGS)
    for block in result["poolings"].values():  # no class colour in the synthetic images: pooling changes nothing
        assert block["auc"] == 1.0
        assert all(e["invalid"] == pytest.approx(all_invalid) for e in block["hard"])
        assert block["soft"][0] == {"penalty": 1e-9, **result["unfiltered"]}  # a negligible penalty
        assert block["soft"][1]["invalid"] == pytest.approx(all_invalid)
        assert all(e["sorted"] == pytest.approx(1 - e["invalid"]) for e in block["hard"] + block["soft"])
    assert result["unfiltered"]["invalid"] > all_invalid
    best = result["candidate"]
    assert best is not None and best["invalid"] == pytest.approx(all_invalid) and best["pooling"] == "cell"
    assert best["rule"] == "hard" and best["threshold"] == fr.SWEEP[0]  # the first of the equal best
    crafted = {"unfiltered": {"invalid": 0.1, "sorted": 0.5}, "poolings": {
        "cell": {"hard": [{"threshold": 0.1, "invalid": 0.01, "sorted": 0.4},  # safest, but sorts less
                          {"threshold": 0.5, "invalid": 0.05, "sorted": 0.5}],
                 "soft": [{"penalty": 1.0, "invalid": 0.05, "sorted": 0.52}]},
        "mean": {"hard": [{"threshold": 0.2, "invalid": 0.07, "sorted": 0.6}], "soft": []}}}
    assert fr.penalty_candidate(crafted, 0.06) == {"pooling": "cell", "rule": "soft", "penalty": 1.0,
                                                   "invalid": 0.05, "sorted": 0.52}  # the tie goes to the more sorted
    assert fr.penalty_candidate(crafted, 0.08)["pooling"] == "cell"
    assert fr.penalty_candidate(crafted, 0.04) is None
    zero = fr.penalty_check(tmp_path / "data", type("Zero", (Dark,), {"risk": lambda self, obs: np.zeros((20, 30))})(
        None), str(tmp_path / "p.zip"))
    rows = [e for b in zero["poolings"].values() for e in b["hard"] + b["soft"]]
    assert all(e["invalid"] == zero["unfiltered"]["invalid"] for e in rows)
    assert fr.main(["penalty", "--data", str(tmp_path / "episodes"), "--model", str(tmp_path / "m.pt"),
                    "--checkpoint", "p.zip", "--out", str(tmp_path / "x.json")]) == 2
    assert not (tmp_path / "x.json").exists()


def test_spread_labels_give_each_object_cell_its_nearest_labelled_pick():
    """One object (row 1, columns 1-5) with a fall labelled at column 1 and a safe pick at column 3: columns 1-2
    take the fall, 3-5 the safe pick, and none is equidistant except column 2 (one cell from each), which takes
    their mean; a labelled cell on no object keeps its label; an object with no label gets none."""
    from shelf_env.camera.heightmap import CLASS_RGB

    obs = np.full((1, 4, 5, 8), 255, np.uint8)
    obs[0, :3, 1, 1:6] = np.asarray(CLASS_RGB[1])[:, None]
    obs[0, :3, 3, 6:8] = np.asarray(CLASS_RGB[0])[:, None]  # an object no pick was labelled on
    split = fr.Split(th.as_tensor(obs), th.tensor([0, 0, 0]), th.tensor([1 * 8 + 1, 1 * 8 + 3, 4 * 8 + 0]),
                     th.tensor([1.0, 0.0, 1.0]), np.array([2]), np.array([0, 1, 0]))
    spread = fr.spread_labels(split)
    got = {int(c): float(v) for c, v in zip(spread.cell, spread.label)}
    assert got == {9: 1.0, 10: 0.5, 11: 0.0, 12: 0.0, 13: 0.0, 32: 1.0}
    assert (spread.state == 0).all() and spread.obs is split.obs and spread.sorted_change is None


def test_training_with_spread_labels_reports_its_targets(tmp_path):
    """``--spread`` trains on `spread_labels`'s targets: on the synthetic dataset (no class colour, so no object)
    they are the labelled picks themselves, and the report says so."""
    synthetic_teacher_shards(tmp_path / "data")
    report = fr.train_fall_risk(tmp_path / "data", tmp_path / "s.pt", init=None, epochs=1, batch=8, val_fraction=0.25,
                                spread=True)
    assert report["spread"] is True and report["train_targets"] == report["train_probes"] == 54 * 8
    assert fr.main(["train", "--data", str(tmp_path / "data"), "--out", str(tmp_path / "t.pt"), "--init", "none",
                    "--epochs", "1", "--val-fraction", "0.25", "--spread"]) == 0
    assert fr.FallRiskModel.load(tmp_path / "t.pt").info["spread"] is True
