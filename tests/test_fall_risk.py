"""The learned fall-risk filter: labels that are what the env's step does, a resumable collection, a
model that learns a cell-wise rule and picks its threshold on held-out episodes, a filter that
masks exactly the risky picks, and its evaluation policy name ``<zip>+fall-filter``."""

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from research import fall_risk as fr
from sb3_pixeldqn import PixelDoubleDQN
from sb3_pixeldqn.loop_breaker import LoopBreaker
from shelf_env import policies
from shelf_env.evaluation import protocol as ev


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


def test_the_auc_and_the_threshold():
    labels = np.array([0, 0, 1, 1])
    assert fr.auc(labels, np.array([0.1, 0.2, 0.8, 0.9])) == 1.0
    assert fr.auc(labels, np.array([0.9, 0.8, 0.2, 0.1])) == 0.0
    assert fr.auc(labels, np.array([0.5, 0.5, 0.5, 0.5])) == 0.5
    assert 0.2 < fr.pick_threshold(labels, np.array([0.1, 0.2, 0.8, 0.9])) <= 0.8


MAPS, H, W = 2, 3, 4  # map 0: pick, map 1: push


class Scores:
    """A greedy pixel policy over fixed scores that honours masks (as a PixelDoubleDQN does)."""

    observation_space = spaces.Box(0, 255, (4, H, W), np.uint8)
    action_space = spaces.Discrete(MAPS * H * W)

    def __init__(self, scores):
        self.scores = np.asarray(scores, float).reshape(-1)

    def predict(self, obs, state=None, episode_start=None, deterministic=True, action_masks=None):
        masks = np.ones(self.scores.size, bool) if action_masks is None else np.asarray(action_masks, bool)
        return np.array(int(np.where(masks, self.scores, -np.inf).argmax())), state


class FixedRisk:
    threshold = 0.5

    def __init__(self, risk):
        self.map = np.asarray(risk, float)

    def risk(self, obs):
        return self.map


def test_the_filter_masks_exactly_the_risky_picks():
    scores = np.arange(MAPS * H * W, dtype=float)[::-1].copy()  # best: pick (0, 0), then (0, 1), ...
    obs = np.zeros((4, H, W), np.uint8)
    risk = np.zeros((H, W))
    risk[0, 0] = 0.9  # the best pick is risky
    filt = fr.FallFilter(Scores(scores), FixedRisk(risk), ("pick", "push"), H, W)
    masks = np.ones(MAPS * H * W, bool)
    assert int(filt.predict(obs, action_masks=masks)[0]) == 1  # the next-best pick
    assert filt.stats == {"masked": 1, "unfiltered": 0}
    masks[1] = False  # the caller's masks still hold
    assert int(filt.predict(obs, action_masks=masks)[0]) == 2
    everything = fr.FallFilter(Scores(scores), FixedRisk(np.ones((H, W))), ("pick", "push"), H, W)
    assert int(everything.predict(obs, action_masks=np.ones(MAPS * H * W, bool))[0]) == H * W  # a push
    only_picks = np.zeros(MAPS * H * W, bool)
    only_picks[:H * W] = True
    assert int(everything.predict(obs, action_masks=only_picks)[0]) == 0  # nothing safe: unfiltered
    assert everything.stats == {"masked": 2, "unfiltered": 1}
    assert int(everything.predict(obs)[0]) == 0  # a policy without env masks, every pick risky: unfiltered
    safe = fr.FallFilter(Scores(scores), FixedRisk(np.zeros((H, W))), ("pick", "push"), H, W)
    assert int(safe.predict(obs, action_masks=np.ones(MAPS * H * W, bool))[0]) == 0
    with pytest.raises(ValueError, match="pick map"):
        fr.FallFilter(Scores(scores), FixedRisk(risk), ("push", "pull"), H, W)
    with pytest.raises(ValueError, match="shape"):
        filt.predict(np.zeros((1, 4, H, W), np.uint8))
    other = FixedRisk(risk)
    other.info = {"obs_shape": [4, 2 * H, 2 * W]}
    with pytest.raises(ValueError, match=r"trained on observations of shape \(4, 6, 8\)"):
        fr.FallFilter(Scores(scores), other, ("pick", "push"), H, W)


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


def test_the_command_line_names_bad_input_in_one_line_and_writes_nothing(tmp_path, capsys):
    assert fr.main(["train", "--data", str(tmp_path), "--out", str(tmp_path / "m.pt")]) == 2
    assert "no collected episodes" in capsys.readouterr().err and not (tmp_path / "m.pt").exists()
    missing = str(tmp_path / "x.zip")
    assert fr.main(["collect", "--out", str(tmp_path / "d"), "--episodes", "1", "--model", missing]) == 2
    assert "neither one of" in capsys.readouterr().err and not (tmp_path / "d").exists()
    assert fr.main(["check", "--data", str(tmp_path), "--model", str(tmp_path / "m.pt"), "--checkpoint", "p.zip"]) == 2
    assert "does not exist" in capsys.readouterr().err
