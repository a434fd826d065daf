"""`shelf_env.training.model_card`: a card from a run's progress and episodes and an evaluation's results."""

import csv
import json

from shelf_env.evaluation import protocol as ev
from shelf_env.training.config import PRESETS
from shelf_env.training.model_card import main, model_card, recipe_terms


def fake_run(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    progress = {"wall_seconds": 7200.0, "timesteps": 9000, "episodes": 4, "demo_seconds": 75.0,
                "config": PRESETS["p_s"].to_dict(),
                "curriculum": {"value": 3, "history": [[0, 1], [500, 2], [1200, 3]], "capped": [1200], "finished": 9000,
                               "greedy_history": [[1000, 2, 0.9], [1500, 3, 0.85]]},
                "amendments": [{"timesteps": 1100, "changes": {"max_stage_timesteps": 5000}}],
                "sessions": [{"machine": "Linux x86_64, 2 CPUs", "torch_threads": 2, "device": "cpu",
                              "started": "2026-11-24T00:00:00+00:00", "timesteps": 0, "wall_seconds": 0.0,
                              "buffer_kept": False}]}
    (run / "progress.json").write_text(json.dumps(progress))
    with open(run / "episodes.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["timestep", "wall_seconds", "num_objects", "success", "actions", "return", "fell"])
        w.writerows([[3, 60, 1, 1, 1, 0, 0], [510, 600, 2, 1, 2, -1, 0], [1210, 1500, 3, 0, 40, -40, 0]])
    results = tmp_path / "eval"
    records = [ev.EpisodeRecord(p, "ycb", n, 0, run_, s, 5, 3, False)
               for p, ok in (("p_s", (True, True)), ("h-d", (True, False))) for n in (3, 4)
               for run_, s in enumerate(ok)]
    ev.write_results(results, records, {})
    zip_path = tmp_path / "p_s.zip"
    zip_path.write_bytes(b"x" * 2048)
    return run, zip_path, results


def test_card_has_training_history_and_the_evaluation_beside_other_policies(tmp_path):
    run, zip_path, results = fake_run(tmp_path)
    card = model_card(run, zip_path, results, "bash scripts/train_model.sh p_s")
    assert card.startswith("# `p_s.zip`: PixelDoubleDQN, P+S")
    assert "`bash scripts/train_model.sh p_s`" in card and "9000 env steps, 2.00 h" in card
    assert "Linux x86_64, 2 CPUs, 2 torch threads, cpu" in card
    # stage, step, minutes, and whether the gate or the stage cap promoted it
    assert "| 2 | 500 | 10 | greedy gate |" in card and "| 3 | 1200 | 25 | stage cap (5000 steps) |" in card
    assert "amended from env step 1100 (`shelf-train --amend`): `max_stage_timesteps = 5000`" in card
    assert "85 % at N = 3, step 1500" in card
    assert "curriculum ended at env step 9000, when N = 3 had trained its 5000 steps" in card
    assert "| objects | N | p_s SR % | h-d SR % | p_s AE | p_s mAE |" in card
    assert "| ycb | 3 | 100.0 ± 0.0 | 50.0 ± 0.0 | 0.60 | 0.60 |" in card


def test_cli_writes_the_card_and_refuses_a_results_folder_without_the_model(tmp_path, capsys):
    run, zip_path, results = fake_run(tmp_path)
    out = tmp_path / "card.md"
    assert main([str(run), "--zip", str(zip_path), "--results", str(results), "--out", str(out)]) == 0
    assert out.read_text().startswith("# `p_s.zip`")
    other = tmp_path / "other.zip"
    other.write_bytes(b"x")
    assert main([str(run), "--zip", str(other), "--results", str(results), "--out", str(tmp_path / "o.md")]) == 2
    assert "has no rows of policy 'other'" in capsys.readouterr().out
    assert not (tmp_path / "o.md").exists()


def test_cli_writes_several_cards_under_one_title_and_refuses_unmatched_counts(tmp_path, capsys):
    run, zip_path, results = fake_run(tmp_path)
    s_zip = tmp_path / "s.zip"
    s_zip.write_bytes(b"x" * 1024)
    out = tmp_path / "README.md"
    assert main([str(run), str(run), "--zip", str(zip_path), str(s_zip), "--command", "a p_s", "a s",
                 "--out", str(out)]) == 0
    text = out.read_text()
    assert text.startswith("# Pretrained models: `p_s.zip`, `s.zip`")
    # each card keeps its content, its headings one level down
    assert "\n## `p_s.zip`: PixelDoubleDQN" in text and "\n## `s.zip`: PixelDoubleDQN" in text
    assert "\n### Training" in text and "`a s`" in text and text.count("| 2 | 500 | 10 | greedy gate |") == 2
    assert main([str(run), str(run), "--zip", str(zip_path), "--out", str(tmp_path / "bad.md")]) == 2
    assert "one --zip and one --command per run: 2 runs, 1 zips" in capsys.readouterr().out
    assert not (tmp_path / "bad.md").exists()


def test_a_distilled_cards_recipe_says_whether_the_teacher_term_took_a_set() -> None:
    report = {"teacher_radius": 2, "teacher_temperature": 1.0, "progress": True, "augment": ["mirror"]}
    assert recipe_terms(report)[1] == "a cross-entropy on the teacher's choice (temperature 1) on its 5 x 5-cell square"
    with_set = recipe_terms({**report, "teacher_set": True, "teacher_temperature": 0.0, "margin": 2.0})
    assert with_set[1] == ("a margin 2 on the teacher's choice and every labelled action as good by the labels on its "
                           "5 x 5-cell square")
