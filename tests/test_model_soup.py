"""research/model_soup.py: the soup's weights are the ingredients' mean, it loads and plays as a PixelDoubleDQN,
its report names the ingredients, and ingredients of different layouts are refused with nothing written."""

from __future__ import annotations

import hashlib
import json
import pathlib

import numpy as np
import pytest
import torch as th
from pixel_envs import FindTheSquareEnv

from research import model_soup
from sb3_pixeldqn import PixelDoubleDQN


def save_model(path: pathlib.Path, seed: int, widths: tuple[int, ...] = (4, 8, 8)) -> pathlib.Path:
    env = FindTheSquareEnv(shape=(4, 12, 20), n_maps=1)
    model = PixelDoubleDQN("FCNPolicy", env, policy_kwargs=dict(maps=[("pick", 0)], widths=widths), seed=seed)
    model.save(path)
    return path


def test_the_soup_is_the_mean_of_its_ingredients(tmp_path: pathlib.Path) -> None:
    paths = [save_model(tmp_path / f"m{i}.zip", seed=i) for i in range(3)]
    report = model_soup.soup(paths, tmp_path / "soup.zip")
    soup = PixelDoubleDQN.load(tmp_path / "soup.zip", device="cpu")
    states = [PixelDoubleDQN.load(p, device="cpu").q_net.state_dict() for p in paths]
    assert not all(th.equal(states[0][k], states[1][k]) for k in states[0])  # three different models
    for name, value in soup.q_net.state_dict().items():
        expected = sum(s[name].double() for s in states) / 3
        assert th.allclose(value.double(), expected, atol=1e-6), name
        assert th.equal(value, soup.q_net_target.state_dict()[name])  # the target is the soup too
    obs = FindTheSquareEnv(shape=(4, 12, 20), n_maps=1).reset(seed=0)[0]
    action, _ = soup.predict(obs, deterministic=True)
    assert 0 <= int(action) < 240
    written = json.loads((tmp_path / "soup.soup.json").read_text())
    assert written == report
    assert [i["sha256"] for i in written["ingredients"]] == [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]


def test_the_mean_keeps_equal_counters_and_refuses_different_ones() -> None:
    a = {"w": th.tensor([1.0, 3.0]), "n": th.tensor(5)}
    b = {"w": th.tensor([3.0, 5.0]), "n": th.tensor(5)}
    mean = model_soup.mean_state([a, b])
    assert np.allclose(mean["w"].numpy(), [2.0, 4.0]) and int(mean["n"]) == 5
    with pytest.raises(ValueError, match="'n' differ"):
        model_soup.mean_state([a, {"w": b["w"], "n": th.tensor(6)}])


@pytest.mark.parametrize("case, message", [("layout", "does not share"), ("one", "at least two"),
                                           ("missing", "no such checkpoint"), ("suffix", "must end in .zip")])
def test_bad_ingredients_are_refused_by_name_and_nothing_is_written(tmp_path: pathlib.Path, case: str,
                                                                   message: str) -> None:
    a = save_model(tmp_path / "a.zip", seed=0)
    b = save_model(tmp_path / "b.zip", seed=1, widths=(4, 8, 8) if case != "layout" else (4, 6, 8))
    paths = {"layout": [a, b], "one": [a], "missing": [a, tmp_path / "nope.zip"], "suffix": [a, b]}[case]
    out = tmp_path / ("soup.pt" if case == "suffix" else "soup.zip")
    assert model_soup.main([*map(str, paths), "--out", str(out)]) == 2
    with pytest.raises(ValueError, match=message):
        model_soup.soup(paths, out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.zip", "b.zip"]
