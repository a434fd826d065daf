"""rl-zoo3: the generated hyper-parameter file, a 48-step training run through rl-zoo3's own entry
point (model zip where rl-zoo3 saves it), then rl-zoo3's enjoy and record_video on the result."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import gymnasium as gym
import pytest
import yaml

pytest.importorskip("rl_zoo3", reason="the zoo extra: pip install '.[zoo]'")

from sb3_pixeldqn import PixelDoubleDQN  # noqa: E402
from shelf_env.training.config import PRESETS, make_env  # noqa: E402
from shelf_env.training.zoo import HYPERPARAMS, RecipeCallback, write_hyperparams, zoo_hyperparams  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_committed_yml_is_generated_from_the_recipe_preset(tmp_path):
    assert HYPERPARAMS.read_text() == write_hyperparams(tmp_path / "x.yml")
    entry = yaml.safe_load(HYPERPARAMS.read_text())["ShelfSort-v0"]
    recipe = PRESETS["recipe"]
    assert entry["learning_rate"] == recipe.learning_rate and entry["target_update_interval"] == 100
    assert entry["env_kwargs"]["pixel_size"] == recipe.pixel_size
    (callback,) = entry["callback"]
    fields = callback["shelf_env.training.zoo.RecipeCallback"]
    assert fields["augment"] == ["mirror", "permute"] and fields["demo_policy"] == "h-a" and fields["gate"] == "greedy"
    # every TrainConfig field is in the file exactly once (but `extra`), so the preset is the one place
    flat = set(entry) | set(entry["env_kwargs"]) | set(fields) | {"widths", "relabel", "noop", "noop_penalty"}
    assert {f for f in recipe.to_dict() if f != "extra"} <= flat


def _run(script: str, *args: str, cwd: pathlib.Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / "examples" / script), *args], cwd=cwd, capture_output=True,
                          text=True, timeout=600)


def test_48_steps_with_rl_zoo3_then_enjoy_and_record(tmp_path):
    config = PRESETS["recipe"].replace(demo_steps=8, widths=(4, 8, 8), learning_starts=8, eval_every=16,
                                       eval_episodes=2, buffer_size=200, pixel_size=0.02)
    conf = tmp_path / "small.yml"
    conf.write_text(yaml.safe_dump(zoo_hyperparams(config, n_timesteps=48), sort_keys=False))
    common = ["--algo", "pixel_double_dqn", "--env", "ShelfSort-v0", "-f", str(tmp_path / "logs")]
    out = _run("zoo_train.py", *common, "--gym-packages", "shelf_env", "-conf", str(conf), "--eval-freq", "-1",
               "--num-threads", "1", "--seed", "0", cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "demonstrations: h-a" in out.stdout and "curriculum: greedy success" in out.stdout
    zip_path = tmp_path / "logs" / "pixel_double_dqn" / "ShelfSort-v0_1" / "ShelfSort-v0.zip"
    model = PixelDoubleDQN.load(zip_path)
    assert model.num_timesteps >= 48 and model.observation_space.shape == (4, 20, 30)
    assert model.curriculum_state["value"] >= 1 and model.target_update_interval == 100

    enjoy = _run("zoo_enjoy.py", *common, "--gym-packages", "shelf_env", "-n", "5", "--no-render",
                 "--num-threads", "1", cwd=tmp_path)
    assert enjoy.returncode == 0, enjoy.stderr[-3000:]
    record = _run("zoo_record.py", *common, "-n", "3", cwd=tmp_path)
    assert record.returncode == 0, record.stderr[-3000:]
    assert list((zip_path.parent / "videos").glob("*.mp4"))


def test_recipe_callback_takes_the_training_envs_conditions_for_its_greedy_checks():
    env = gym.make("ShelfSort-v0", pixel_size=0.02, safe_picks=True, closed_loop={"stacked": "put back"},
                   min_num_objects=2)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(widths=(4, 8, 8)))
    callback = RecipeCallback(verbose=0, demo_policy=None)
    callback.init_callback(model)
    config = callback._config()
    assert config.safe_picks and config.min_num_objects == 2 and config.pixel_size == 0.02
    assert config.closed_loop["stacked"] == "put back"
    check = make_env(config)  # what the curriculum's greedy checks are built from
    assert check.unwrapped.safe_picks and check.unwrapped.drag_watch == env.unwrapped.drag_watch
    plain = RecipeCallback(verbose=0)
    plain.init_callback(PixelDoubleDQN("FCNPolicy", make_env(PRESETS["recipe"]), policy_kwargs=dict(widths=(4, 8, 8))))
    assert plain._config().closed_loop is False and not plain._config().safe_picks
    check.close()
    env.close()


def test_recipe_callback_refuses_fields_no_run_could_use():
    callback = RecipeCallback(gate="sometimes")
    with pytest.raises(ValueError, match="gate must be one of"):
        PRESETS["recipe"].replace(**callback.fields)
    # the actor process is shelf-train's: under rl-zoo3 it would be silently ignored, so it is refused
    model = PixelDoubleDQN("FCNPolicy", make_env(PRESETS["recipe"]), policy_kwargs=dict(widths=(4, 8, 8)))
    actor = RecipeCallback(verbose=0, actor=True)
    actor.init_callback(model)
    with pytest.raises(ValueError, match="shelf-train --actor"):
        actor.on_training_start({}, {})
    # so is the supervisor of the training env (shelf-train wraps the env it builds; rl-zoo3 builds its own)
    guard = RecipeCallback(verbose=0, guard="h-d-lookahead")
    guard.init_callback(model)
    with pytest.raises(ValueError, match="guard: h-d-lookahead in the yml.*set guard: null"):
        guard.on_training_start({}, {})
    # parallel envs are rl-zoo3's own n_envs; the lookahead teacher needs the one training env itself
    parallel = RecipeCallback(verbose=0, n_envs=4)
    parallel.init_callback(model)
    with pytest.raises(ValueError, match="set the yml's own n_envs"):
        parallel.on_training_start({}, {})
    from stable_baselines3.common.vec_env import DummyVecEnv

    two = PixelDoubleDQN("FCNPolicy", DummyVecEnv([lambda: make_env(PRESETS["recipe"])] * 2),
                         policy_kwargs=dict(widths=(4, 8, 8)))
    teacher = RecipeCallback(verbose=0, demo_policy="h-d-lookahead")
    teacher.init_callback(two)
    with pytest.raises(ValueError, match="probes the simulator of the env it plays in.*2 env"):
        teacher.on_training_start({}, {})


def test_the_hyperparameter_writer_answers_help_without_writing(tmp_path, monkeypatch, capsys):
    from shelf_env.training.zoo import main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0 and "usage: python -m shelf_env.training.zoo" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []
    assert main([str(tmp_path / "zoo.yml")]) == 0
    assert "invalid_reward: -10.0" in (tmp_path / "zoo.yml").read_text()
