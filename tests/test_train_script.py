"""shelf-train (examples/train.py) on the real env for a handful of steps: checkpoints, honest wall time, resume."""

import csv
import json
import time

import numpy as np

from shelf_env.cli import train


def test_checkpoints_count_wall_time_once_and_resume(tmp_path):
    common = ["--out", str(tmp_path), "--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_steps=3"]
    t0 = time.monotonic()
    train.main([*common, "--max-steps", "4"])
    elapsed = time.monotonic() - t0
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 4
    # checkpoints after every step: the recorded total must still be the real time, not a sum of totals
    assert 0 < progress["wall_seconds"] <= elapsed + 1.0
    assert (tmp_path / "model.zip").exists() and (tmp_path / "replay.pkl").exists()
    assert progress["config"]["demo_steps"] == 3 and progress["config"]["pixel_size"] == 0.01

    train.main([*common, "--max-steps", "7"])
    progress2 = json.loads((tmp_path / "progress.json").read_text())
    assert progress2["timesteps"] == 7 and progress2["wall_seconds"] > progress["wall_seconds"]
    assert progress2["curriculum"]["value"] == 1
    sessions = progress2["sessions"]  # one record per run of the command, for the model card
    assert [s["timesteps"] for s in sessions] == [0, 4] and sessions[1]["buffer_kept"]
    assert sessions[0]["device"] == "cpu" and sessions[0]["torch_threads"] == 1
    with open(tmp_path / "episodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == progress2["episodes"]
    assert all(int(a["timestep"]) < int(b["timestep"]) for a, b in zip(rows, rows[1:]))
    # the demonstrations were collected once and survive the resume through replay.pkl
    from sb3_pixeldqn import PixelDoubleDQN

    model = PixelDoubleDQN.load(tmp_path / "model.zip")
    model.load_replay_buffer(tmp_path / "replay.pkl")
    assert model.replay_buffer.demonstrations.n_stored >= 3 and model.demo_timesteps == 3


def test_mirror_keeps_a_committable_copy_and_a_fresh_machine_resumes_from_it(tmp_path):
    """--mirror: everything but replay.pkl is copied; a run dir without a checkpoint starts from the
    copy (weights, stage, epsilon, counters), refills its buffer and learns again only after
    learning_starts new steps."""
    run, mirror = tmp_path / "run", tmp_path / "committed"
    common = ["--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8", "8", "--checkpoint-minutes",
              "0", "--threads", "1", "--set", "demo_steps=3", "--mirror", str(mirror)]
    train.main(["--out", str(run), *common, "--max-steps", "4"])
    assert sorted(p.name for p in mirror.iterdir()) == ["episodes.csv", "model.zip", "progress.json", "tb"]
    assert (run / "replay.pkl").exists() and not (mirror / "replay.pkl").exists()
    first = json.loads((mirror / "progress.json").read_text())
    assert first["timesteps"] == 4

    fresh = tmp_path / "fresh_machine"
    train.main(["--out", str(fresh), *common, "--max-steps", "7"])
    progress = json.loads((fresh / "progress.json").read_text())
    assert progress["timesteps"] == 7 and progress["wall_seconds"] > first["wall_seconds"]
    assert json.loads((mirror / "progress.json").read_text())["timesteps"] == 7  # mirrored again
    from sb3_pixeldqn import PixelDoubleDQN

    model = PixelDoubleDQN.load(fresh / "model.zip")
    assert model.learning_starts == 4 + 2  # refilled before learning again
    model.load_replay_buffer(fresh / "replay.pkl")
    assert model.replay_buffer.demonstrations.n_stored >= 3  # demonstrations collected again
    assert model.replay_buffer.size() == 3  # only the new steps: the old buffer was not committed


def test_amend_changes_a_resumed_runs_curriculum_and_records_when(tmp_path, capsys):
    """--amend: a resumed run takes up a new stage cap from its next step (recorded in progress.json
    with that step); a fresh run, a field the model depends on or a bad value is refused in one line."""
    common = ["--out", str(tmp_path), "--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_steps=3", "--set", "eval_every=1000"]
    assert train.main([*common, "--max-steps", "3", "--amend", "max_stage_timesteps=2"]) == 2
    assert "use --set for a new run" in capsys.readouterr().err and not (tmp_path / "progress.json").exists()
    train.main([*common, "--max-steps", "3"])
    before = (tmp_path / "progress.json").read_text()
    for bad, message in ((["--amend", "widths=[8,8,8]"], "cannot change ['widths']"),
                         (["--amend", "max_stage_timesteps=-3"], "max_stage_timesteps")):
        assert train.main([*common, "--max-steps", "9", *bad]) == 2
        assert message in capsys.readouterr().err
        assert (tmp_path / "progress.json").read_text() == before  # nothing written
    train.main([*common, "--max-steps", "9", "--amend", "max_stage_timesteps=2"])
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["amendments"] == [{"timesteps": 3, "changes": {"max_stage_timesteps": 2}}]
    assert progress["config"]["max_stage_timesteps"] == 2
    # N = 1 had lasted 3 steps when the cap of 2 arrived: promoted at once, then every 2 steps
    history = progress["curriculum"]["history"]
    assert history[0] == [0, 1] and history[1] == [4, 2] and [n for _, n in history] == list(range(1, len(history) + 1))
    assert progress["curriculum"]["capped"] == [t for t, _ in history[1:]]
    # the same amendment again changes nothing and records nothing
    train.main([*common, "--max-steps", "10", "--amend", "max_stage_timesteps=2"])
    assert len(json.loads((tmp_path / "progress.json").read_text())["amendments"]) == 1


def test_a_capped_curriculum_ends_the_run_after_its_last_stage(tmp_path, capsys):
    """max_stage_timesteps caps the last stage too: the run stops there, a resume has nothing to do,
    and a resume with a longer cap (--amend) trains the last stage on."""
    common = ["--out", str(tmp_path), "--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_steps=3", "--set", "eval_every=1000",
              "--set", "start_objects=1", "--set", "max_objects=2", "--max-steps", "50"]
    assert train.main([*common, "--set", "max_stage_timesteps=2"]) == 0
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 4 and progress["curriculum"]["finished"] == 4
    assert progress["curriculum"]["history"] == [[0, 1], [2, 2]]
    capsys.readouterr()
    before = (tmp_path / "progress.json").read_text()
    assert train.main(common) == 0
    assert "the curriculum is over" in capsys.readouterr().out
    assert (tmp_path / "progress.json").read_text() == before  # nothing ran, nothing written
    assert train.main([*common, "--amend", "max_stage_timesteps=5"]) == 0
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 7 and progress["curriculum"]["finished"] == 7


def test_init_from_starts_a_new_run_from_trained_weights(tmp_path, capsys):
    import torch as th

    from sb3_pixeldqn import PixelDoubleDQN

    common = ["--learning-starts", "50", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_steps=2"]
    trained = tmp_path / "a"
    train.main([*common, "--out", str(trained), "--max-steps", "2", "--learning-starts", "1"])
    zip_path = trained / "model.zip"
    # a new run under another configuration (safe picks), from those weights; no learning before step 50
    assert train.main([*common, "--out", str(tmp_path / "b"), "--max-steps", "2", "--init-from", str(zip_path),
                       "--set", "safe_picks=true"]) == 0
    a, b = PixelDoubleDQN.load(zip_path), PixelDoubleDQN.load(tmp_path / "b" / "model.zip")
    for (name, wa), (_, wb) in zip(a.policy.state_dict().items(), b.policy.state_dict().items()):
        assert th.equal(wa, wb), name
    progress = json.loads((tmp_path / "b" / "progress.json").read_text())
    assert progress["init_from"]["path"] == str(zip_path) and len(progress["init_from"]["sha256"]) == 64
    assert progress["config"]["safe_picks"] is True and b.num_timesteps == 2
    # a fresh run from scratch does not start from them
    train.main([*common, "--out", str(tmp_path / "c"), "--max-steps", "1", "--seed", "1"])
    c = PixelDoubleDQN.load(tmp_path / "c" / "model.zip")
    assert not all(th.equal(x, y) for x, y in zip(a.policy.state_dict().values(), c.policy.state_dict().values()))
    capsys.readouterr()
    # bad input: one line, nothing written
    assert train.main([*common, "--out", str(tmp_path / "d"), "--init-from", str(tmp_path / "none.zip")]) == 2
    assert "none.zip" in capsys.readouterr().err
    pick_only = ["--init-from", str(zip_path), "--primitives", "pick"]
    assert train.main([*common, "--out", str(tmp_path / "d"), *pick_only]) == 2
    assert "trained with primitives ('pick', 'push')" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_actor_process_trains_checkpoints_and_resumes(tmp_path):
    # --actor: the env steps come from an actor process; checkpoints, episodes.csv and resume work as
    # without it, and --amend actor=false turns it off in a resumed run
    common = ["--out", str(tmp_path), "--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "2", "--set", "demo_steps=3"]
    assert train.main([*common, "--actor", "--max-steps", "6"]) == 0
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 6 and progress["config"]["actor"] is True
    session = progress["sessions"][0]
    assert session["actor"] is True and session["torch_threads"] == 2
    assert train.main([*common, "--max-steps", "9"]) == 0  # the run's own configuration: still the actor
    assert train.main([*common, "--max-steps", "11", "--amend", "actor=false"]) == 0
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 11 and [s["actor"] for s in progress["sessions"]] == [True, True, False]
    assert progress["amendments"] == [{"timesteps": 9, "changes": {"actor": False}}]
    with open(tmp_path / "episodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == progress["episodes"] and all(int(r["timestep"]) <= 11 for r in rows)
    from sb3_pixeldqn import PixelDoubleDQN

    model = PixelDoubleDQN.load(tmp_path / "model.zip")
    model.load_replay_buffer(tmp_path / "replay.pkl")
    # every consumed step is stored (and relabelled twins) but the one each session stops at (SB3
    # stops before storing it)
    assert model.replay_buffer.size() >= 11 - 3 and model.replay_buffer.demonstrations.n_stored >= 3


def test_parallel_envs_keep_the_replay_ratio_and_a_run_moves_between_machines(tmp_path, capsys):
    # --n-envs 2: two env processes, two gradient steps per collection step; resumed with --n-envs 1
    # (a run moving from a many-core machine to two cores), recorded as an amendment, one again
    from sb3_pixeldqn import PixelDoubleDQN

    common = ["--out", str(tmp_path), "--learning-starts", "2", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_steps=3"]
    assert train.main([*common, "--n-envs", "2", "--max-steps", "8"]) == 0
    assert "collecting from 2 env processes; learner on cpu" in capsys.readouterr().out
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 8 and progress["config"]["n_envs"] == 2
    assert progress["sessions"][0]["n_envs"] == 2 and progress["sessions"][0]["device"] == "cpu"
    model = PixelDoubleDQN.load(tmp_path / "model.zip")
    # 4 collection steps of 2 envs (timesteps 2, 4, 6, 8): those at 4 and 6 are past learning_starts
    # and followed by 2 gradient steps each; the run stops at its budget of 8 before training again
    assert model.gradient_steps == 2 and model._n_updates == 2 * 2
    with open(tmp_path / "episodes.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == progress["episodes"] and all(int(r["timestep"]) <= 8 for r in rows)

    assert train.main([*common, "--n-envs", "1", "--max-steps", "10"]) == 0
    progress = json.loads((tmp_path / "progress.json").read_text())
    assert progress["timesteps"] == 10 and progress["config"]["n_envs"] == 1
    assert progress["amendments"] == [{"timesteps": 8, "changes": {"n_envs": 1}}]
    assert [s["n_envs"] for s in progress["sessions"]] == [2, 1]
    model = PixelDoubleDQN.load(tmp_path / "model.zip")
    assert model.gradient_steps == 1 and model._n_updates == 2 * 2 + 1  # step 9 trains once, 10 stops
    assert train.main([*common, "--n-envs", "0", "--max-steps", "12"]) == 2  # a clear error, nothing run
    assert "n_envs must be an integer >= 1" in capsys.readouterr().err


def test_a_supervised_run_replaces_the_vetoed_actions_and_keeps_them(tmp_path, capsys, monkeypatch):
    """--set guard=...: the learner's steps go through FallGuard (here every push "drops an object",
    every pick is fine): the ring holds only the executed picks, the demonstration store each
    correction's vetoed push and executed pick; guard cannot be amended on a resumed run."""
    from sb3_pixeldqn import PixelDoubleDQN
    from shelf_env import params
    from shelf_env.privileged import lookahead

    real_probe = lookahead.probe_step

    def probe(env, action):
        outcome = real_probe(env, action)
        if env.unwrapped.codec.decode(action)[0].startswith("push"):
            return lookahead.Outcome(params.REWARD_INVALID, True, True, False, "x", outcome.next_obs)
        return outcome

    monkeypatch.setattr(lookahead, "probe_step", probe)
    common = ["--out", str(tmp_path), "--learning-starts", "100", "--buffer-size", "200", "--widths", "4", "8", "8",
              "--checkpoint-minutes", "0", "--threads", "1", "--set", "demo_policy=null", "--set", "eval_every=1000",
              "--set", "guard=h-d-lookahead", "--start-objects", "2"]
    assert train.main([*common, "--max-steps", "8"]) == 0
    assert "supervised by h-d-lookahead" in capsys.readouterr().out
    model = PixelDoubleDQN.load(tmp_path / "model.zip")
    model.load_replay_buffer(tmp_path / "replay.pkl")
    ring, demos = model.replay_buffer, model.replay_buffer.demonstrations
    maps = [model.policy.maps[int(a) // (ring.observations.shape[-2] * ring.observations.shape[-1])][0]
            for a in ring.actions[:ring.n_stored, 0, 0]]
    assert set(maps) == {"pick"} and model.n_corrections >= 1  # the random masked actions included pushes
    vetoed = ~demos.expert[:demos.n_stored]
    assert vetoed.sum() == model.n_corrections
    # -10 each, less the buffer's no-op penalty where the vetoed push would have changed nothing
    # (whether a random push moves anything depends on the machine's physics)
    from sb3_pixeldqn.buffers import unchanged
    noop = np.array([unchanged(o, n) for o, n in zip(demos.observations[:demos.n_stored][vetoed, 0],
                                                      demos.next_observations[:demos.n_stored][vetoed, 0])])
    penalty = demos.noop_penalty if demos.noop != "keep" else 0.0
    assert np.allclose(demos.rewards[:demos.n_stored][vetoed, 0], -10 - penalty * noop)
    assert train.main([*common, "--max-steps", "9", "--amend", "guard=null"]) == 2
    assert "cannot change ['guard']" in capsys.readouterr().err


def test_min_num_objects_mixes_the_sizes_of_the_learners_env(tmp_path, monkeypatch, capsys):
    from shelf_env.env import ShelfSortEnv

    drawn: list[tuple[int | None, int, int]] = []
    original = ShelfSortEnv.episode_size

    def recording(self: ShelfSortEnv) -> int:
        n = original(self)
        drawn.append((self.min_num_objects, self.num_objects, n))
        return n

    monkeypatch.setattr(ShelfSortEnv, "episode_size", recording)
    assert train.main(["--out", str(tmp_path), "--learning-starts", "50", "--buffer-size", "200", "--widths", "4",
                       "8", "8", "--checkpoint-minutes", "0", "--threads", "1", "--max-steps", "3", "--set",
                       "demo_steps=8", "--set", "min_num_objects=1", "--start-objects", "3"]) == 0
    assert "demonstrations: h-a at N = 1..3 (drawn)" in capsys.readouterr().out
    mixed = [n for low, high, n in drawn if low == 1]
    assert mixed and all(1 <= n <= 3 for n in mixed) and all(high == 3 for low, high, _ in drawn if low == 1)
    assert json.loads((tmp_path / "progress.json").read_text())["config"]["min_num_objects"] == 1
