"""research/distilled_veto.py: the shipped policy chooses only among the actions the veto model values within
delta of its best allowed one; the settings beside a checkpoint are checked by name."""

import json
import pathlib

import numpy as np
import pytest
from gymnasium import spaces

from research import distilled_veto as dv
from shelf_env import policies

SHAPE, N = (4, 3, 4), 2 * 3 * 4


class Scores:
    """A policy with fixed scores: the masked argmax (SB3's predict with action_masks)."""

    observation_space = spaces.Box(0, 255, SHAPE, np.uint8)
    action_space = spaces.Discrete(N)

    def __init__(self, scores):
        self.scores = np.asarray(scores, float)

    def predict(self, obs, state=None, episode_start=None, deterministic=True, action_masks=None):
        masks = np.ones(N, bool) if action_masks is None else np.asarray(action_masks, bool)
        return np.array(int(np.where(masks, self.scores, -np.inf).argmax())), state


class FixedQ(Scores):
    """A veto model: ``policy.q_map_values`` returns fixed maps."""

    def __init__(self, q):
        super().__init__(q)
        self.policy = self

    def q_map_values(self, obs):
        return self.scores.reshape(2, 3, 4)


def test_the_policy_chooses_among_the_actions_within_delta_of_the_vetos_best():
    obs = np.zeros(SHAPE, np.uint8)
    own = np.arange(N, dtype=float)  # the policy's favourite: the last action, then the one before
    q = np.zeros(N)
    q[N - 1], q[N - 2], q[3] = -3.0, -0.5, 1.0  # the veto's best: 3; the policy's favourite 4 below it
    veto = dv.DistilledVeto(Scores(own), FixedQ(q), delta=1.0)
    assert int(veto.predict(obs, action_masks=np.ones(N, bool))[0]) == N - 3  # 0.0 >= 1 - 1; N-2 and N-1 vetoed
    assert veto.stats == {"decisions": 1, "vetoed": 1}
    masks = np.ones(N, bool)
    masks[3] = False  # the veto's best is measured over the allowed actions only: now 0.0, so -0.5 is kept
    assert int(veto.predict(obs, action_masks=masks)[0]) == N - 2
    wide = dv.DistilledVeto(Scores(own), FixedQ(q), delta=5.0)
    assert int(wide.predict(obs, action_masks=np.ones(N, bool))[0]) == N - 1  # nothing vetoed: the policy's own
    assert wide.stats == {"decisions": 1, "vetoed": 0}
    strict = dv.DistilledVeto(Scores(own), FixedQ(q), delta=0.0)
    assert int(strict.predict(obs, action_masks=np.ones(N, bool))[0]) == 3  # the veto's greedy choice
    with pytest.raises(ValueError, match="delta must be a finite number >= 0"):
        dv.DistilledVeto(Scores(own), FixedQ(q), delta=-1.0)
    with pytest.raises(ValueError, match="shape"):
        veto.predict(np.zeros((1, *SHAPE), np.uint8))


def test_make_writes_the_settings_and_the_registry_checks_them(tmp_path: pathlib.Path, capsys) -> None:
    base, model = tmp_path / "base.zip", tmp_path / "veto.zip"
    base.write_bytes(b"base")
    model.write_bytes(b"veto")
    out = tmp_path / "m" / "p_s_v_d1.zip"
    assert dv.main(["make", "--base", str(base), "--veto", str(model), "--delta", "1", "--out", str(out)]) == 0
    settings = json.loads(dv.veto_path(out).read_text())
    assert out.read_bytes() == b"base" and settings["delta"] == 1.0 and settings["veto"] == str(model)
    assert dv.read_settings(str(out)) == (model, 1.0)
    assert policies.policy_label(f"{out}{dv.VETO}") == "p_s_v_d1+veto"
    model.write_bytes(b"another")  # retrained: not the model the settings were made with
    with pytest.raises(ValueError, match="is not the one the settings were made with"):
        policies.check_policy(f"{out}{dv.VETO}")
    with pytest.raises(ValueError, match="no settings at"):
        policies.check_policy(f"{base}{dv.VETO}")
    with pytest.raises(ValueError, match="is not a checkpoint"):
        policies.check_policy(f"h-d{dv.VETO}")
    for args, message in ((["--delta", "nan"], "--delta must be a finite number"),
                          (["--veto", str(tmp_path / "none.zip")], "does not exist"),
                          (["--out", str(tmp_path / "x.pt")], "--out must be a .zip")):
        argv = ["make", "--base", str(base), "--veto", str(model), "--delta", "1", "--out", str(tmp_path / "x.zip")]
        for flag, value in zip(args[::2], args[1::2]):
            argv[argv.index(flag) + 1] = value
        assert dv.main(argv) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "x.zip").exists() and not (tmp_path / "x.pt").exists()


def test_gaps_are_measured_from_the_best_allowed_action(tmp_path: pathlib.Path, capsys) -> None:
    q = np.array([[3.0, 1.0, 9.0, 2.5], [0.0, -1.0, -2.0, 5.0]])
    masks = np.array([[True, True, False, True], [True, True, True, False]])  # 9.0 and 5.0 not allowed
    gap = dv.gaps(q, masks, np.array([0, 0, 0, 1, 1]), np.array([0, 1, 3, 1, 2]))
    assert gap.tolist() == [0.0, 2.0, 0.5, 1.0, 2.0]
    (tmp_path / "d.zip").write_bytes(b"")
    assert dv.main(["margins", str(tmp_path / "d.zip"), "--data", str(tmp_path)]) == 2
    assert "d.distill.json does not exist" in capsys.readouterr().err


@pytest.mark.parametrize("text, message", [
    ("{not json", "not JSON"),
    ('{"veto": "m.zip", "delta": 1}', "no 'veto_sha256' setting"),
    ('{"veto": "m.zip", "veto_sha256": "x", "delta": "wide"}', "wrong type"),
    ('{"veto": "m.zip", "veto_sha256": "x", "delta": -1}', "delta must be a finite number >= 0"),
])
def test_a_broken_settings_file_is_refused_by_name(tmp_path: pathlib.Path, text: str, message: str) -> None:
    base = tmp_path / "base.zip"
    base.write_bytes(b"base")
    dv.veto_path(base).write_text(text)
    with pytest.raises(ValueError, match=message) as err:
        policies.check_policy(f"{base}{dv.VETO}")
    assert str(dv.veto_path(base)) in str(err.value)
