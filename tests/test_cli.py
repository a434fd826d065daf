"""The console scripts: installed, bad input answered in one line with exit status 2, nothing
written; shelf-demo writes its GIF."""

from __future__ import annotations

import importlib.metadata
import shutil

import numpy as np
import pytest
from PIL import Image

from shelf_env.cli import demo, evaluate, train
from shelf_env.training.config import PRESETS

SCRIPTS = {"shelf-demo": demo.main, "shelf-train": train.main, "shelf-evaluate": evaluate.main}


def test_console_scripts_are_installed_and_point_at_the_mains():
    points = {e.name: e for e in importlib.metadata.entry_points(group="console_scripts")}
    for name, fn in SCRIPTS.items():
        assert name in points, f"{name} is not installed (pip install .)"
        assert points[name].load() is fn
        assert shutil.which(name) is not None


def _one_line_error(capsys, prog: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"{prog}: error: "), err
    return err[0]


@pytest.mark.parametrize("argv, match", [
    (["--policy", "no-such-policy"], "neither one of"),
    (["--policy", "missing/model.zip"], "neither one of"),
    (["--policy", "random"], "not random"),
    (["--policy", "h-d", "--n", "0"], "N must be in 1..14"),
    (["--policy", "h-d", "--n", "15"], "N must be in 1..14"),
    (["--policy", "h-d", "--seed", "-1"], "--seed must be >= 0"),
    (["--policy", "h-d", "--out", "x.png"], ".gif"),
])
def test_demo_bad_input(tmp_path, capsys, monkeypatch, argv, match):
    monkeypatch.chdir(tmp_path)
    assert demo.main(argv) == 2
    assert match in _one_line_error(capsys, "shelf-demo")
    assert list(tmp_path.iterdir()) == []


def test_demo_writes_a_gif_of_the_episode(tmp_path, capsys):
    out = tmp_path / "d.gif"
    assert demo.main(["--policy", "h-d", "--n", "2", "--seed", "0", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "action  1:" in printed and f"wrote {out}" in printed
    gif = Image.open(out)
    actions = printed.count("  action ")
    assert gif.n_frames == actions + 1 and gif.size == (3 * demo.PANEL[0], demo.PANEL[1] + 26)
    assert [p.name for p in tmp_path.iterdir()] == ["d.gif"]


def test_demo_overlays_the_model_q_maps_under_the_loop_breaker():
    import gymnasium as gym

    from sb3_pixeldqn import LoopBreaker
    from shelf_env.evaluation import protocol as ev

    name = "examples/pretrained/p_s.zip"
    env = gym.make("ShelfSort-v0", num_objects=2, pixel_size=ev.policy_pixel_size(name))
    obs, _ = env.reset(seed=0)
    bare, wrapped = ev.make_policy(name, env), ev.make_policy(name + ev.LOOP_BREAKER, env)
    assert isinstance(wrapped, LoopBreaker)
    q_bare, q_wrapped = demo.q_map_values_of(bare)(obs), demo.q_map_values_of(wrapped)(obs)
    assert q_wrapped.shape == (3, 40, 60)  # pick, push right, push left at 1 cm cells
    np.testing.assert_allclose(q_wrapped, q_bare)  # the same weights, read through the breaker
    shipped = ev.make_policy(name + "+geometry-filter+pick-guard" + ev.LOOP_BREAKER, env)  # as the card says
    np.testing.assert_allclose(demo.q_map_values_of(shipped)(obs), q_bare)  # through the breaker, guard and filter
    assert demo.q_map_values_of(ev.make_policy("h-d", env)) is None
    env.close()


def test_demo_defaults_to_the_shipped_policy_as_its_card_says_to_play_it(tmp_path, monkeypatch):
    shelf = demo.pathlib.Path(__file__).parents[1] / "examples" / "pretrained"
    assert demo.default_policy().endswith("examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker")
    # a policy whose files are not all there is passed over for the next: here the filter's risk is missing
    (tmp_path / "a").mkdir()
    shutil.copy(shelf / "p_s.zip", tmp_path / "a" / "p_s.zip")
    monkeypatch.setattr(demo, "DEFAULT_POLICIES", ("a/p_s.zip+geometry-filter+loop-breaker", "a/p_s.zip"))
    monkeypatch.chdir(tmp_path)
    assert demo.default_policy(tmp_path) == "a/p_s.zip"
    shutil.copy(shelf / "p_s.geometry_risk.pt", tmp_path / "a" / "p_s.geometry_risk.pt")
    assert demo.default_policy(tmp_path) == "a/p_s.zip+geometry-filter+loop-breaker"


@pytest.mark.parametrize("argv, match", [
    (["--policies", "nope"], "neither one of"),
    (["--policies", "h-d", "--ns", "0"], "N must be in 1..14"),
    (["--policies", "h-d", "--runs", "0"], "--runs, --seeds and --workers must be >= 1"),
])
def test_evaluate_bad_input(tmp_path, capsys, argv, match):
    out = tmp_path / "eval"
    assert evaluate.main([*argv, "--out", str(out)]) == 2
    assert match in _one_line_error(capsys, "shelf-evaluate")
    assert not out.exists()


@pytest.mark.parametrize("argv, match", [
    (["--set", "noop=bad"], "TrainConfig.noop must be one of"),
    (["--set", "lr=1"], "unknown TrainConfig fields"),
    (["--start-objects", "9"], "start_objects <= max_objects"),
    (["--hours", "0"], "--hours and --max-steps must be > 0"),
])
def test_train_bad_input(tmp_path, capsys, argv, match):
    out = tmp_path / "run"
    assert train.main(["--out", str(out), *argv]) == 2
    assert match in _one_line_error(capsys, "shelf-train")
    assert not out.exists()


def test_train_config_refuses_values_no_run_could_use():
    recipe = PRESETS["recipe"]
    for change, match in (({"gate": "eager"}, "gate must be one of"), ({"relabel": "some"}, "relabel"),
                          ({"demo_policy": "h-x"}, "demo_policy"), ({"primitives": ("pick", "rotate")}, "primitives"),
                          ({"pixel_size": 0.05}, "pixel_size"), ({"batch_size": 0}, "batch_size"),
                          ({"object_set": "kitchen"}, "object_set")):
        with pytest.raises(ValueError, match=match):
            recipe.replace(**change)
