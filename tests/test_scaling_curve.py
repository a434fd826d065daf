"""research/scaling_curve.py: the distilled models sit on the curve by their training states, the starting
model at 0, reference policies as dashed lines; the table shows each cell's counts."""

import json
import pathlib

from research import scaling_curve
from shelf_env.evaluation import falls


def cell(policy: str, n: int, decisions: int, invalid: int, sorted_: int) -> dict:
    episodes = [falls.FallEpisode(r, decisions // 4, 0, 0, r < sorted_, -1) for r in range(4)]
    summary = falls.cell_summary(episodes) | {"decisions": decisions, "invalid": invalid, "fell": invalid,
                                             "invalid_rate": invalid / decisions, "fall_rate": invalid / decisions,
                                             "episodes_invalid": min(invalid, 4)}
    return {"policy": policy, "num_objects": n, "seed": 2000, "object_set": "ycb", **summary}


def test_the_curve_orders_models_by_states_and_keeps_references_apart(tmp_path: pathlib.Path) -> None:
    start = "examples/pretrained/p_s.zip"
    for stem, states, loss, augment in (("p_s_d100", 100, 5.0, []), ("p_s_d50", 50, 6.0, []),
                                        ("p_s_d100_aug", 100, 4.0, ["MirrorWidth(...)"])):
        report = {"init": start, "train_states": states, "augment": augment, "masks": bool(augment),
                  "progress": bool(augment),
                  "history": [{"epoch": 0, "val": {"loss": 9.0}}, {"epoch": 1, "val": {"loss": loss}}]}
        (tmp_path / f"{stem}.distill.json").write_text(json.dumps(report))
    cells = [cell(start, 8, 100, 20, 1), cell("runs/p_s_d100.zip", 8, 100, 5, 3),
             cell("runs/p_s_d50.zip", 8, 100, 10, 2), cell("h-d", 8, 80, 4, 2),
             cell("runs/p_s_d100_aug.zip", 8, 100, 2, 4), cell("runs/p_s_d100_aug.zip+loop-breaker", 8, 100, 1, 4)]
    (tmp_path / "falls.json").write_text(json.dumps({str(i): c for i, c in enumerate(cells)}))
    data = scaling_curve.rows(*scaling_curve.load(tmp_path))
    assert [(r["policy"], r["states"], r["val_loss"]) for r in data] == [
        ("p_s", 0, 9.0), ("p_s_d50", 50, 6.0), ("p_s_d100", 100, 5.0), ("p_s_d100_aug", 100, 4.0),
        ("p_s_d100_aug+loop-breaker", 100, 4.0), ("h-d", None, None)]
    text = scaling_curve.table(data)
    assert data[4]["wrapped"] and not data[3]["wrapped"]
    assert "| p_s_d100_aug | 100 | augmented, teacher over allowed actions, progress | 4.00 |" \
        " 2.0 % / 2.0 % (2/100; 2/4 ep.) | 100 % (4) |" in text
    assert "| p_s_d100 | 100 | as stored, teacher over labels | 5.00 | 5.0 % / 5.0 % (5/100; 4/4 ep.) |" \
        " 75 % (4) |" in text
    assert "| h-d | - | - | - | 5.0 % / 5.0 % (4/80; 4/4 ep.) | 50 % (4) |" in text
    png = tmp_path / "curve.png"
    assert scaling_curve.main([str(tmp_path), "--png", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    held_out = tmp_path / "held_out"  # the same models measured elsewhere, their reports read from here
    held_out.mkdir()
    (held_out / "falls.json").write_text(json.dumps({"0": cell("runs/p_s_d100.zip", 8, 50, 1, 2)}))
    assert scaling_curve.rows(*scaling_curve.load(held_out))[0]["states"] is None  # no report there
    (only,) = scaling_curve.rows(*scaling_curve.load(held_out, tmp_path))
    assert (only["policy"], only["states"], only["val_loss"]) == ("p_s_d100", 100, 5.0)


def test_the_recipe_names_every_option_that_differs_from_the_defaults() -> None:
    report = {"augment": ["MirrorWidth(...)"], "masks": True, "progress": True, "anchor": 1.0, "teacher_radius": 2,
              "teacher_weight": 5.0}
    assert scaling_curve.recipe(report) == \
        "augmented, teacher over allowed actions, progress, anchor 1, teacher radius 2, teacher weight 5"
    assert scaling_curve.recipe(report | {"teacher_radius": 0, "teacher_weight": 1.0}) == \
        "augmented, teacher over allowed actions, progress, anchor 1"
    assert scaling_curve.recipe(report | {"teacher_radius": 0, "teacher_weight": 1.0, "epochs": 24,
                                          "shards": ["s00_00000.npz", "s01_00000.npz"]}) == \
        "augmented, teacher over allowed actions, progress, anchor 1, 24 epochs, + series s01"
