"""The teacher dataset: shards resume, every label is what stepping its action really does, bad shards are
refused by name, and a collection stopped mid-shard leaves nothing behind."""

from __future__ import annotations

import json
import os
import pathlib

import numpy as np
import pytest

from shelf_env.privileged import dataset

MODEL = "examples/pretrained/v1/p_s.zip"


@pytest.fixture(scope="module")
def one_shard(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("teacher")
    assert dataset.collect(out, hours=1.0, ns=(2,), model_path=MODEL, episodes_per_shard=1, max_shards=1,
                           max_probes=8) == 1
    return out


def test_shard_holds_states_labels_and_the_scene(one_shard: pathlib.Path) -> None:
    shard = dataset.load_shard(dataset.shard_path(one_shard, 0, 0))
    a = shard.arrays
    assert shard.num_states >= 1 and shard.num_labels > shard.num_states  # several labels per state
    assert a["obs"].dtype == np.uint8 and a["obs"].shape[1:] == (4, 40, 60)
    assert shard.meta["episodes"][0]["num_objects"] == 2
    for t in range(shard.num_states):  # the model's greedy action is labelled in every state, once
        sources = [dataset.SOURCES[i] for i in a["label_source"][a["label_state"] == t]]
        assert sources.count("greedy") == 1
    for t in range(shard.num_states):  # the teacher's choice is labelled in its state, at most max_probes + 1
        labelled = a["label_action"][a["label_state"] == t]
        assert a["teacher_action"][t] in labelled and len(labelled) <= 9
    executed = [int(x) for x in a["executed_action"] if x >= 0]
    assert executed == shard.meta["episodes"][0]["actions"]
    import hashlib

    assert shard.meta["model_sha256"] == hashlib.sha256(pathlib.Path(MODEL).read_bytes()).hexdigest()


def test_with_explore_1_the_driving_model_is_followed_wherever_it_stays_valid(tmp_path: pathlib.Path) -> None:
    assert dataset.collect(tmp_path, hours=1.0, ns=(3,), model_path=MODEL, episodes_per_shard=1, max_shards=1,
                           max_probes=4, explore=1.0) == 1
    shard = dataset.load_shard(dataset.shard_path(tmp_path, 0, 0))
    a = shard.arrays
    assert shard.meta["explore"] == 1.0
    for t in range(shard.num_states):
        mine = a["label_state"] == t
        greedy = mine & (a["label_source"] == dataset.SOURCES.index("greedy"))
        assert greedy.sum() == 1
        if a["label_valid"][greedy][0]:  # the model's action is executed; the teacher only rescues falls
            assert a["executed_action"][t] == a["label_action"][greedy][0]
        else:
            assert a["executed_action"][t] != a["label_action"][greedy][0]


def test_a_policy_under_its_wrappers_drives_as_it_plays(tmp_path: pathlib.Path) -> None:
    """The shipped P+S under its filter, guard and breaker as the driver: the shard names it and the digest of every
    file it reads, and each state's greedy label is what that policy chooses there when asked as an evaluation asks
    (the stored observation's masks; ``episode_start`` at each episode's first state; its memory carried through the
    episode and forgotten at the next)."""
    import gymnasium as gym

    from shelf_env.camera.heightmap import observation_masks
    from shelf_env.evaluation.protocol import policy_digest
    from shelf_env.policies import make_policy

    shipped = "examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker"
    assert dataset.collect(tmp_path, hours=1.0, ns=(3,), model_path=shipped, episodes_per_shard=2, max_shards=1,
                           max_probes=4, explore=1.0) == 1
    shard = dataset.load_shard(dataset.shard_path(tmp_path, 0, 0))
    a = shard.arrays
    assert len(set(a["state_episode"].tolist())) == 2
    assert shard.meta["model"] == shipped
    assert shard.meta["model_sha256"] == policy_digest(shipped) != policy_digest("examples/pretrained/p_s.zip")
    env = gym.make("ShelfSort-v0", num_objects=3, object_set="train", primitives=dataset.PRIMITIVES,
                   pixel_size=dataset.PIXEL_SIZE)
    try:
        policy = make_policy(shipped, env)
        names = env.unwrapped.map_names  # type: ignore[attr-defined]
        for t in range(shard.num_states):
            masks = observation_masks(a["obs"][t], dataset.PIXEL_SIZE, names).reshape(-1)
            first = t == 0 or a["state_episode"][t] != a["state_episode"][t - 1]
            action, _ = policy.predict(a["obs"][t], deterministic=True, action_masks=masks,
                                       episode_start=np.array([first]))
            greedy = (a["label_state"] == t) & (a["label_source"] == dataset.SOURCES.index("greedy"))
            assert int(np.asarray(action).reshape(-1)[0]) == int(a["label_action"][greedy][0])
    finally:
        env.close()


def test_every_label_equals_a_real_step(one_shard: pathlib.Path) -> None:
    shard = dataset.load_shard(dataset.shard_path(one_shard, 0, 0))
    states, labels, mismatches = dataset.replay_states(shard)
    assert mismatches == []
    assert (states, labels) == (shard.num_states, shard.num_labels)


def test_collection_resumes_without_redoing_shards(one_shard: pathlib.Path, tmp_path: pathlib.Path) -> None:
    first = dataset.shard_path(one_shard, 0, 0)
    out = tmp_path / "teacher"
    out.mkdir()
    (out / first.name).write_bytes(first.read_bytes())
    assert dataset.collect(out, ns=(2,), model_path=None, episodes_per_shard=1, max_shards=1, max_probes=4) == 0
    assert dataset.collect(out, ns=(2,), model_path=None, episodes_per_shard=1, max_shards=2, max_probes=4) == 1
    assert (out / first.name).read_bytes() == first.read_bytes()
    assert [p.name for p in dataset.shard_files(out)] == ["s00_00000.npz", "s00_00001.npz"]
    text = dataset.status(out)
    assert "2 shards, 2 scenes" in text and "| 2 | 2 |" in text
    states = sum(dataset.load_shard(p).num_states for p in dataset.shard_files(out))
    assert f"| s00 | 2 | {states} |" in text
    assert text.splitlines()[-1] == "all of it, named for a reproducible run: --max-shards s00:2"
    second = dataset.load_shard(out / "s00_00001.npz")
    hours = float(second.meta["seconds"]) / 3600
    since = dataset.status(out, since="s00:1")  # the second collection alone, with its own clock's rate
    assert "since s00:1: 1 shards, 1 scenes" in since
    assert (f"| s00 | 1 | {second.num_states} | {second.num_labels} | {hours:.2f} | "
            f"{second.num_states / hours:.0f} / {second.num_labels / hours:.0f} |") in since
    assert since.splitlines()[-1] == text.splitlines()[-1]  # the spec still names all of it
    with pytest.raises(ValueError, match="--since asks for 3 shards of series s00"):
        dataset.status(out, since="s00:3")
    (out / "s00_00001.npz").rename(out / "s01_00001.npz")  # series 1 without its shard 0
    text = dataset.status(out)
    assert "--max-shards s00:1,s01:1" in text
    assert text.splitlines()[-1].endswith("until it is collected): s01")


def test_a_collection_killed_mid_shard_leaves_nothing(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def killed(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(dataset, "collect_episode", killed)
    with pytest.raises(KeyboardInterrupt):
        dataset.collect(tmp_path, ns=(1,), model_path=None, max_shards=1)
    assert list(tmp_path.iterdir()) == []

    def torn(path: pathlib.Path, **kwargs: object) -> None:
        path.write_bytes(b"PK\x03\x04 half a shard")
        raise KeyboardInterrupt

    monkeypatch.undo()
    monkeypatch.setattr(dataset, "save_shard", torn)
    with pytest.raises(KeyboardInterrupt):
        dataset.collect(tmp_path, ns=(1,), model_path=None, episodes_per_shard=1, max_shards=1, max_probes=2)
    assert list(tmp_path.iterdir()) == []


def rewrite(src: pathlib.Path, dst: pathlib.Path, **meta_changes: object) -> pathlib.Path:
    with np.load(src) as data:
        arrays = {k: data[k] for k in data.files}
    meta = json.loads(str(arrays.pop("meta")))
    meta.update(meta_changes)
    np.savez_compressed(dst, meta=np.array(json.dumps(meta)), **arrays)
    return dst


def test_bad_shards_are_refused_by_name(one_shard: pathlib.Path, tmp_path: pathlib.Path) -> None:
    good = dataset.shard_path(one_shard, 0, 0)
    truncated = tmp_path / "s00_00000.npz"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(ValueError, match=f"{truncated}.*unreadable"):
        dataset.load_dataset(tmp_path)
    other_env = rewrite(good, tmp_path / "s00_00001.npz", dynamics_version=dataset.DYNAMICS_VERSION + 1)
    with pytest.raises(ValueError, match=f"{other_env}.*dynamics version"):
        dataset.load_shard(other_env)
    five_mm = {"obs_shape": [4, 80, 120], "pixel_size": 0.005, "map_names": ["pick", "push_left", "push_right"]}
    with pytest.raises(ValueError, match="s00_00000.npz: observation layout"):
        dataset.load_shard(good, expect_layout=five_mm)
    with pytest.raises(ValueError, match="format"):
        dataset.load_shard(rewrite(good, tmp_path / "s00_00002.npz", format=0))
    with pytest.raises(ValueError, match="no dataset shards"):
        dataset.load_dataset(tmp_path / "empty")


def test_bad_collect_arguments_are_one_line_errors(capsys: pytest.CaptureFixture[str], tmp_path: pathlib.Path) -> None:
    niceness = os.nice(0)
    assert dataset.main(["collect", "--out", str(tmp_path), "--ns", "0"]) == 2
    assert "ns must be numbers of objects" in capsys.readouterr().err
    assert dataset.main(["collect", "--out", str(tmp_path), "--explore", "1.5", "--model", "none"]) == 2
    assert "explore in [0, 1]" in capsys.readouterr().err
    assert dataset.main(["collect", "--out", str(tmp_path), "--model", str(tmp_path / "missing.zip")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert dataset.main(["collect", "--out", str(tmp_path), "--nice", "20"]) == 2
    assert "niceness must be in 0..19, got 20" in capsys.readouterr().err
    assert os.nice(0) == niceness  # refused before the collection lowered its own priority
    assert list(tmp_path.iterdir()) == []


def test_shards_become_labelled_states_and_distil_into_the_shipped_layout(
        one_shard: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str]) -> None:
    from shelf_env.training import distill as distill_cli

    shard = dataset.load_shard(dataset.shard_path(one_shard, 0, 0))
    labelled = dataset.labelled_states([shard])
    a = shard.arrays
    assert len(labelled.obs) == shard.num_states and len(labelled.label_action) == shard.num_labels
    assert np.all(labelled.label_value[~a["label_valid"]] == -10.0)
    assert np.all(labelled.label_value[a["label_success"]] == 0.0)
    assert np.isnan(labelled.label_value[a["label_valid"] & ~a["label_success"]]).all()
    out = tmp_path / "distilled.zip"
    assert distill_cli.main(["--data", str(one_shard), "--init", MODEL, "--out", str(out), "--epochs", "1",
                             "--val-fraction", "0", "--teacher-radius", "2", "--teacher-weight", "3",
                             "--progress-radius", "1", "--progress-weight", "2", "--teacher-temperature", "0.5",
                             "--seed", "3", "--batch-states", "4", "--teacher-set"]) == 0
    report = json.loads(out.with_suffix(".distill.json").read_text())
    # what reproduces it: a replicate at another seed differs from the first only in this field
    assert report["seed"] == 3 and report["batch_states"] == 4 and report["learning_rate"] is None
    assert report["train_states"] == shard.num_states and report["history"][-1]["train"]["loss"] > 0
    assert report["teacher_radius"] == 2 and report["teacher_weight"] == 3.0 and report["progress_radius"] == 1
    assert report["progress_weight"] == 2.0 and report["teacher_temperature"] == 0.5 and report["margin"] == 1.0
    assert report["teacher_set"] is True
    from sb3_pixeldqn import PixelDoubleDQN

    assert PixelDoubleDQN.load(out).observation_space.shape == (4, 40, 60)
    assert distill_cli.main(["--data", str(one_shard), "--init", str(tmp_path / "none.zip"), "--out",
                             str(tmp_path / "x.zip")]) == 2
    assert distill_cli.main(["--data", str(one_shard), "--init", MODEL, "--out", str(tmp_path / "x.zip"),
                             "--teacher-radius", "-1"]) == 2
    assert "teacher_radius must be a finite number >= 0, got -1" in capsys.readouterr().err
    assert distill_cli.main(["--data", str(one_shard), "--init", MODEL, "--out", str(tmp_path / "x.zip"),
                             "--progress-weight", "-2"]) == 2
    assert "the progress weight must be a finite number >= 0, got -2.0" in capsys.readouterr().err
    assert not (tmp_path / "x.zip").exists()


def test_average_last_saves_the_mean_of_the_last_epochs_weights(one_shard: pathlib.Path, tmp_path: pathlib.Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    import torch

    from sb3_pixeldqn import PixelDoubleDQN
    from shelf_env.training import distill as distill_cli

    def distil(name: str, *extra: str) -> dict[str, torch.Tensor]:
        out = tmp_path / f"{name}.zip"
        assert distill_cli.main(["--data", str(one_shard), "--init", MODEL, "--out", str(out), "--val-fraction", "0",
                                 "--batch-states", "2", *extra]) == 0
        return PixelDoubleDQN.load(out, device="cpu").q_net.state_dict()

    first = distil("one", "--epochs", "1")  # epoch 1 alone (each epoch's batch order comes from seed + epoch)
    second = distil("two", "--epochs", "2")  # the same epoch 1, then epoch 2
    mean = distil("mean", "--epochs", "2", "--average-last", "2", "--last-out", str(tmp_path / "last.zip"))
    assert any(not torch.equal(first[k], second[k]) for k in first)  # the epochs moved the weights
    for k in mean:
        torch.testing.assert_close(mean[k], (first[k] + second[k]) / 2, rtol=1e-5, atol=1e-6)
    report = json.loads((tmp_path / "mean.distill.json").read_text())
    assert report["average_last"] == 2 and report["averaged"] == {"epochs": 2}  # no validation states here
    # --last-out: the same run's last epoch, which is the plain 2-epoch model, with that model's report
    last = PixelDoubleDQN.load(tmp_path / "last.zip", device="cpu").q_net.state_dict()
    assert all(torch.equal(last[k], second[k]) for k in second)
    plain = json.loads((tmp_path / "last.distill.json").read_text())
    assert plain["average_last"] == 1 and "averaged" not in plain and plain["out"] == str(tmp_path / "last.zip")
    assert plain["history"] == report["history"]
    assert distill_cli.main(["--data", str(one_shard), "--init", MODEL, "--out", str(tmp_path / "x.zip"),
                             "--epochs", "2", "--last-out", str(tmp_path / "y.zip")]) == 2
    assert "last_out needs average_last > 1" in capsys.readouterr().err
    assert not (tmp_path / "x.zip").exists() and not (tmp_path / "y.zip").exists()
    assert distill_cli.main(["--data", str(one_shard), "--init", MODEL, "--out", str(tmp_path / "x.zip"),
                             "--epochs", "2", "--average-last", "3"]) == 2
    assert "average_last must be between 1 and the epochs (2), got 3" in capsys.readouterr().err
    assert not (tmp_path / "x.zip").exists()


def test_a_stopped_distillation_goes_on_from_its_last_epoch_to_the_same_weights(
        one_shard: pathlib.Path, tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A run stopped in the last of its three epochs, started again, ends with the weights and history of a run that
    never stopped (the optimiser's state and the running mean, which holds epoch 2 by then, restored); its checkpoint
    is then gone. A checkpoint of other settings, or an unreadable one, is refused by name."""
    import torch

    from sb3_pixeldqn import PixelDoubleDQN
    from shelf_env.training import distill as distill_cli

    args = ["--data", str(one_shard), "--init", MODEL, "--val-fraction", "0", "--batch-states", "2", "--epochs", "3",
            "--average-last", "2"]
    assert distill_cli.main([*args, "--out", str(tmp_path / "whole.zip")]) == 0
    assert not distill_cli.resume_path(tmp_path / "whole.zip").exists()  # a finished run leaves no checkpoint
    real, calls = distill_cli.distill, []

    def stopped_in_epoch_3(*a: object, **k: object) -> object:
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt  # the session ends during the third epoch
        return real(*a, **k)

    monkeypatch.setattr(distill_cli, "distill", stopped_in_epoch_3)
    out = tmp_path / "stopped.zip"
    with pytest.raises(KeyboardInterrupt):
        distill_cli.main([*args, "--out", str(out)])
    checkpoint = distill_cli.resume_path(out)
    assert checkpoint.exists() and not out.exists()
    monkeypatch.setattr(distill_cli, "distill", real)
    assert distill_cli.main([*args, "--seed", "1", "--out", str(out)]) == 2  # other settings: refused
    assert f"{checkpoint} is the checkpoint of a run with other settings (seed)" in capsys.readouterr().err
    assert distill_cli.main([*args, "--out", str(out)]) == 0
    assert '"after_epoch": 2' in capsys.readouterr().out
    whole = PixelDoubleDQN.load(tmp_path / "whole.zip", device="cpu").q_net.state_dict()
    resumed = PixelDoubleDQN.load(out, device="cpu").q_net.state_dict()
    assert all(torch.equal(whole[k], resumed[k]) for k in whole)
    reports = [json.loads((tmp_path / f"{n}.distill.json").read_text()) for n in ("whole", "stopped")]
    assert reports[0]["history"] == reports[1]["history"] and len(reports[1]["history"]) == 3
    assert not checkpoint.exists()
    checkpoint.write_bytes(b"not a checkpoint")
    assert distill_cli.main([*args, "--out", str(out)]) == 2
    assert f"{checkpoint} is not a readable distillation checkpoint" in capsys.readouterr().err


def test_shards_become_exact_transitions_for_the_demonstration_store(one_shard: pathlib.Path) -> None:
    from shelf_env.training import config as cfg

    shard = dataset.load_shard(dataset.shard_path(one_shard, 0, 0))
    a = shard.arrays
    data = dataset.transitions([shard])
    assert len(data) >= 1 and len(data.obs) == shard.num_states
    step = {(int(e), int(t)): i for i, (e, t) in enumerate(zip(a["state_episode"], a["state_step"]))}
    for k in range(len(data)):
        i, action = int(data.state[k]), int(data.action[k])
        label = np.flatnonzero((a["label_state"] == i) & (a["label_action"] == action))
        assert len(label) == 1  # every transition is a labelled action of its state
        valid, success = bool(a["label_valid"][label[0]]), bool(a["label_success"][label[0]])
        if data.done[k]:  # exact terminal outcomes: a fall or the goal
            assert data.next_state[k] == -1 and data.reward[k] == (0.0 if success else -10.0) and (success or not valid)
        else:  # the executed action, and the state stored after it
            assert action == a["executed_action"][i] and valid and not success and data.reward[k] == -1.0
            assert data.next_state[k] == step[(int(a["state_episode"][i]), int(a["state_step"][i]) + 1)]
        assert data.expert[k] == (action == a["teacher_action"][i] == a["executed_action"][i])
    terminal = int((~a["label_valid"] | a["label_success"]).sum())
    assert int(data.done.sum()) == terminal  # every terminal label is kept

    config = cfg.TrainConfig(demo_policy=None, demo_data=str(one_shard), pixel_size=0.01, augment=())
    env = cfg.make_env(config, 2)
    try:
        model = cfg.make_model(config, env)
        assert cfg.load_demonstration_data(model, config, log=lambda line: None) == len(data)
        demos = model.replay_buffer.demonstrations
        assert demos.n_stored == len(data) and int(demos.expert[: len(data)].sum()) == int(data.expert.sum())
        five_mm = cfg.make_model(config.replace(pixel_size=0.005), cfg.make_env(config.replace(pixel_size=0.005), 2))
        with pytest.raises(ValueError, match="demo_data .*observations"):
            cfg.load_demonstration_data(five_mm, config, log=lambda line: None)
    finally:
        env.close()
    with pytest.raises(ValueError, match="demo_data"):
        cfg.TrainConfig(demo_data=str(one_shard))  # beside the default demo_policy h-a


def test_each_shard_series_holds_out_its_own_last_scenes() -> None:
    from shelf_env.training.distill import split_by_scene

    def fake(series: int, episodes_of_states: list[int], n_episodes: int) -> dataset.Shard:
        return dataset.Shard(pathlib.Path(f"s{series:02d}.npz"), {"series": series, "episodes": [{}] * n_episodes},
                             {"state_episode": np.array(episodes_of_states)})

    # series 0: scenes of 2, 1, 3, 2 states (two shards); series 1: scenes of 1 and 2 states
    shards = [fake(0, [0, 0, 1], 2), fake(0, [0, 0, 0, 1, 1], 2), fake(1, [0, 1, 1], 2)]
    train, val = split_by_scene(shards, 0.5)
    assert val == [3, 4, 5, 6, 7, 9, 10]  # series 0's last two scenes (states 3-7), series 1's last (9, 10)
    assert train == [0, 1, 2, 8]
    assert split_by_scene(shards, 0.0) == (list(range(11)), [])
    with pytest.raises(ValueError, match="leave none for training"):
        split_by_scene(shards[2:], 0.99)


def test_max_shards_names_a_growing_datasets_past_per_series() -> None:
    shards = [dataset.Shard(pathlib.Path(f"s{k:02d}_{i:05d}.npz"), {}, {}) for k, i in
              ((0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (2, 0))]
    names = [s.path.name[:9] for s in dataset.select_shards(shards, "s00:2,s01:1")]
    assert names == ["s00_00000", "s00_00001", "s01_00000"]
    assert len(dataset.select_shards(shards, 4)) == len(dataset.select_shards(shards, "4")) == 4
    assert dataset.select_shards(shards, None) == shards
    with pytest.raises(ValueError, match="asks for 3 shards of series s01; the dataset holds 2"):
        dataset.select_shards(shards, "s01:3")
    with pytest.raises(ValueError, match="a number or"):
        dataset.select_shards(shards, "first:3")


def test_driver_progress_counts_the_greedy_and_teacher_labels_of_each_state(one_shard: pathlib.Path) -> None:
    from research import driver_progress

    shard = dataset.load_shard(dataset.shard_path(one_shard, 0, 0))
    a = shard.arrays
    greedy = a["label_source"] == dataset.SOURCES.index("greedy")
    (row,) = driver_progress.series_rows([shard]).values()
    assert row["states"] == shard.num_states and row["sha256"] == shard.meta["model_sha256"][:12]
    assert row["valid"] == int(a["label_valid"][greedy].sum())
    assert row["greedy_progress"] == int((a["label_valid"] & (a["label_dsorted"] > 0))[greedy].sum())
    assert row["greedy_progress"] <= row["valid"] and row["teacher_progress"] <= row["any_progress"] <= row["states"]
    assert f"| s00 | p_s.zip ({row['sha256']}) | {shard.num_states} |" in driver_progress.table({"s00": row})


def test_distillation_refuses_a_later_shard_of_another_layout_by_name(one_shard: pathlib.Path, tmp_path: pathlib.Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    from shelf_env.training import distill as distill_cli

    good = dataset.shard_path(one_shard, 0, 0)
    (tmp_path / good.name).write_bytes(good.read_bytes())
    layout = dict(dataset.load_shard(good).meta["layout"], pixel_size=0.005)
    other = rewrite(good, tmp_path / "s01_00000.npz", layout=layout)
    assert distill_cli.main(["--data", str(tmp_path), "--init", MODEL, "--out", str(tmp_path / "x.zip")]) == 2
    assert f"dataset shard {other}: observation layout" in capsys.readouterr().err
    assert not (tmp_path / "x.zip").exists()


def test_a_soup_of_distilled_models_and_their_validation_losses(one_shard: pathlib.Path, tmp_path: pathlib.Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    """research/model_soup.py on two distilled replicates: its validation losses are distill's own (the same split
    and loss), and the soup's is reported beside them."""
    import shutil

    from research import model_soup
    from shelf_env.training import distill as distill_cli

    data = tmp_path / "data"
    data.mkdir()
    shard = dataset.shard_path(one_shard, 0, 0)
    for name in ("s00_00000.npz", "s00_00001.npz"):  # two scenes: one trains, the last is validation
        shutil.copy(shard, data / name)
    loss = ["--teacher-radius", "2", "--teacher-temperature", "1"]
    models = []
    for seed in (0, 1):
        out = tmp_path / f"d{seed}.zip"
        assert distill_cli.main(["--data", str(data), "--init", MODEL, "--out", str(out), "--epochs", "1",
                                 "--val-fraction", "0.5", "--seed", str(seed), "--batch-states", "4", *loss]) == 0
        models.append(out)
    capsys.readouterr()
    soup = tmp_path / "soup.zip"
    assert model_soup.main([*map(str, models), "--out", str(soup), "--val-shards", "s00:2", "--data", str(data),
                            "--val-fraction", "0.5", *loss]) == 0
    rows = {row["model"]: row for row in map(json.loads, capsys.readouterr().out.splitlines())}
    assert list(rows) == [*map(str, models), str(soup)]
    for model in models:
        own = json.loads(model.with_suffix(".distill.json").read_text())["history"][-1]["val"]
        assert rows[str(model)]["loss"] == pytest.approx(own["loss"], abs=1e-4)
    assert np.isfinite(rows[str(soup)]["loss"]) and rows[str(soup)]["loss"] != rows[str(models[0])]["loss"]
    assert json.loads((tmp_path / "soup.soup.json").read_text())["ingredients"][1]["path"] == str(models[1])


def test_series_table_counts_pushes_and_the_teacher_s_share_per_series(one_shard: pathlib.Path,
                                                                          tmp_path: pathlib.Path) -> None:
    from research.series_actions import series_table

    with np.load(dataset.shard_path(one_shard, 0, 0)) as data:
        arrays = {k: data[k] for k in data.files}
    cells = int(np.prod(arrays["obs"].shape[2:]))
    n = len(arrays["teacher_action"])
    picks = arrays["teacher_action"] % cells  # the same cells, on the pick map
    # series 0: the teacher picks and is executed; series 5: the teacher picks, a push is executed instead
    np.savez_compressed(tmp_path / "s00_00000.npz", **{**arrays, "teacher_action": picks, "executed_action": picks})
    np.savez_compressed(tmp_path / "s05_00000.npz",
                        **{**arrays, "teacher_action": picks, "executed_action": picks + cells})
    rows = {line.split(" | ")[0].strip("| "): line.split(" | ")[1:] for line in series_table(tmp_path).splitlines()[2:]}
    assert set(rows) == {"s00", "s05"}
    assert rows["s00"][:4] == [str(n), "0.0 %", "0.0 %", "100.0 %"]
    assert rows["s05"][:4] == [str(n), "0.0 %", "100.0 %", "0.0 %"]
    with pytest.raises(ValueError, match="no dataset shards"):
        series_table(tmp_path / "empty")


def test_a_checkpoint_records_the_teacher_set_only_where_it_is_on(tmp_path: pathlib.Path) -> None:
    """A checkpoint written before ``teacher_set`` existed recorded the loss without it; it still resumes under the
    same loss (the option off), and one written with the option on is refused by a run without it."""
    import dataclasses

    import torch

    from sb3_pixeldqn.distill import LossOptions
    from shelf_env.training import distill as distill_cli

    loss = LossOptions(teacher_radius=2, teacher_temperature=1.0)
    old = {k: v for k, v in dataclasses.asdict(loss).items() if k != "teacher_set"}  # as written before the option
    path = tmp_path / "old.resume.pt"
    torch.save({"settings": {"loss": old}, "epoch": 3}, path)
    assert distill_cli.load_checkpoint(path, {"loss": distill_cli.loss_settings(loss)})["epoch"] == 3
    torch.save({"settings": {"loss": distill_cli.loss_settings(dataclasses.replace(loss, teacher_set=True))}}, path)
    with pytest.raises(ValueError, match="checkpoint of a run with other settings \\(loss\\)"):
        distill_cli.load_checkpoint(path, {"loss": distill_cli.loss_settings(loss)})


def test_teacher_ties_counts_labels_as_good_as_the_teachers_off_its_square(one_shard: pathlib.Path,
                                                                           tmp_path: pathlib.Path) -> None:
    from research.teacher_ties import count_ties

    with np.load(dataset.shard_path(one_shard, 0, 0)) as data:
        arrays = {k: data[k] for k in data.files}
    h, w = arrays["obs"].shape[2:]
    state, action = arrays["label_state"], arrays["label_action"]
    first = state == 0
    teacher = int(arrays["teacher_action"][0])
    assert teacher >= 0 and (action[first] == teacher).any()
    # state 0: every label valid and sorting one (the teacher's too); every other state: nothing sorted, no set
    arrays = {**arrays, "label_valid": np.ones_like(arrays["label_valid"]),
              "label_dsorted": np.where(first, 1, 0).astype(arrays["label_dsorted"].dtype)}
    np.savez_compressed(tmp_path / "s00_00000.npz", **arrays)
    shard = dataset.load_shard(tmp_path / "s00_00000.npz")
    m, r, c = action // (h * w), action // w % h, action % w
    tm, tr, tc = teacher // (h * w), teacher // w % h, teacher % w
    off = first & ((m != tm) | (np.abs(r - tr) > 2) | (np.abs(c - tc) > 2))
    ties = count_ties([shard], radius=2)
    assert ties.states == int((arrays["teacher_action"] >= 0).sum()) and ties.sorted_one == 1
    assert ties.ties == int(off.sum()) > 0 and ties.with_ties == 1
    assert sum(ties.sources.values()) == ties.ties
    assert count_ties([shard], radius=100).ties == int((first & (m != tm)).sum())  # a square as large as the map


def test_push_guard_stats_count_the_drivers_greedy_actions_by_primitive_and_outcome(one_shard: pathlib.Path,
                                                                                  tmp_path: pathlib.Path) -> None:
    from research.push_guard import greedy_stats, sorted_pushes, stats_table

    with np.load(dataset.shard_path(one_shard, 0, 0)) as data:
        arrays = {k: data[k] for k in data.files}
    h, w = arrays["obs"].shape[2:]
    greedy = arrays["label_source"] == dataset.SOURCES.index("greedy")
    states = np.unique(arrays["label_state"][greedy])
    assert len(states) == len(arrays["obs"])  # a driver's greedy action is labelled first at every state
    # the last state's greedy action made a push-left at the same cell (this driver picks at N = 2); every greedy
    # label valid; picks sort one, pushes unsort one
    last = int(np.flatnonzero(greedy & (arrays["label_state"] == states[-1]))[0])
    action = arrays["label_action"].copy()
    action[last] = action[last] % (h * w) + h * w
    arrays["label_action"] = action
    is_pick = arrays["label_action"] // (h * w) == 0
    arrays = {**arrays, "label_valid": np.ones_like(arrays["label_valid"]),
              "label_fell": np.zeros_like(arrays["label_fell"]),
              "label_dsorted": np.where(is_pick, 1, -1).astype(arrays["label_dsorted"].dtype)}
    np.savez_compressed(tmp_path / "s07_00000.npz", **arrays)
    counts = greedy_stats(tmp_path, "s07")
    picks, pushes = int((greedy & is_pick).sum()), int((greedy & ~is_pick).sum())
    assert (counts["pick"], counts.get("push", 0)) == (picks, pushes) and picks > 0 and pushes > 0
    assert counts["pick_sorted"] == picks and counts.get("pick_fell", 0) == 0
    assert counts.get("push_unsorted", 0) == pushes and counts.get("push_sorted", 0) == 0
    names = tuple(dataset.load_shard(tmp_path / "s07_00000.npz").meta["layout"]["map_names"])
    guarded = sum(bool(sorted_pushes(arrays["obs"][s], names)[a]) for s, a in
                  zip(arrays["label_state"][greedy & ~is_pick], arrays["label_action"][greedy & ~is_pick]))
    assert counts.get("push_guarded", 0) == guarded and counts.get("push_free", 0) == pushes - guarded
    # a push state has a good pick wherever a labelled pick there is valid (all are) and sorts one (all do)
    push_states = arrays["label_state"][greedy & ~is_pick]
    assert counts.get("push_state_good_pick", 0) == sum(bool((is_pick & (arrays["label_state"] == s)).any())
                                                        for s in push_states)
    assert f"{len(states)} states" in stats_table(counts, "s07")
    with pytest.raises(ValueError, match="no shards of series 's08'"):
        greedy_stats(tmp_path, "s08")
