"""shelf_env.training.ship: only finished runs ship, as loadable zips of their layout, with the model card."""

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
    assert ship(None, finished_run, out) == [out / "p_s.zip"]
    model = PixelDoubleDQN.load(out / "p_s.zip")  # no other file
    assert model.num_timesteps == 4 and model.curriculum_state["finished"] == 4
    card = (out / "README.md").read_text()
    assert card.startswith("# `p_s.zip`: PixelDoubleDQN, P+S") and "`bash scripts/train_model.sh p_s`" in card
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
