"""research/ablation.py: rows on disk are skipped, the report tabulates them and draws the curves."""

import json

from research import ablation
from shelf_env.evaluation import protocol as ev


def row(name: str, seed: int, sr_train: float) -> dict:
    metrics = {"scenes": 10, "sorted": int(sr_train / 10), "sr": sr_train, "actions_per_success": 2.5,
               "noop_share": 0.01, "fell": 0}
    return {"row": name, "seed": seed, "description": ablation.ROWS[name][1], "overrides": {}, "config": {},
            "minutes": 30, "wall_seconds": 1800.0, "env_steps": 5000, "demo_steps": 400, "gradient_steps": 4950,
            "curriculum": {"value": 3, "greedy_history": [[500, 3, 0.6], [1000, 3, 0.9]]},
            "heldout": {"train": metrics, "ycb": dict(metrics, sr=sr_train - 10)}}


def test_rows_on_disk_are_skipped_and_reported(tmp_path, monkeypatch, capsys):
    rows = tmp_path / "rows"
    rows.mkdir()
    (rows / "recipe_s0.json").write_text(json.dumps(row("recipe", 0, 96.0)))
    (rows / "no-demos_s0.json").write_text(json.dumps(row("no-demos", 0, 40.0)))
    # H-d's cells on disk (as research/check_recipe.py writes them): 10/10 in 2.2 actions, 9/10 on YCB
    for object_set, actions, successes in (("train", [2] * 8 + [3] * 2, 10), ("ycb", [2] * 10, 9)):
        ev.save_cell(ev.cell_path(tmp_path, "h-d", object_set, 3, ablation.HELDOUT_SEED, 10),
                     [ev.EpisodeRecord("h-d", object_set, 3, ablation.HELDOUT_SEED, run, run < successes, a, 3, False)
                      for run, a in enumerate(actions)])
    monkeypatch.setattr(ablation, "run_row", lambda *a, **k: (_ for _ in ()).throw(AssertionError("trained")))
    doc = tmp_path / "learning.md"
    doc.write_text(f"intro\n{ablation.BEGIN}\nold table\n{ablation.END}\noutro\n")
    monkeypatch.setattr(ablation, "DOC", doc)
    ablation.main(["--rows", "recipe", "no-demos", "--out", str(tmp_path), "--scenes", "10"])
    out = capsys.readouterr().out
    assert "recipe_s0: on disk, skipped" in out and "no-demos_s0: on disk, skipped" in out
    table = (tmp_path / "ablation.md").read_text().splitlines()
    assert table[2].startswith("| recipe | 0 | the recipe | 96 | 86 | 2.50 (2.20) |")  # recipe first
    assert table[3].startswith("| no-demos | 0 |")
    assert table[-1].startswith("| H-d | - | heuristic | 100 | 90 |")
    assert (tmp_path / "learning_curves.png").stat().st_size > 1000
    text = doc.read_text()
    assert "old table" not in text and "| recipe | 0 |" in text and text.endswith("outro\n")
