"""research/scaling_curve.py: the distilled models sit on the curve by their training states, the starting
model at 0, reference policies as dashed lines; the table shows each cell's counts."""

import dataclasses
import json
import pathlib

import pytest

from research import scaling_curve
from shelf_env.evaluation import falls
from shelf_env.evaluation.protocol import EpisodeRecord, load_cells


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
    (tmp_path / "falls_30.json").write_text(json.dumps({"0": cell("runs/p_s_d50.zip", 8, 300, 3, 4)}))
    out = tmp_path / "table30.md"
    assert scaling_curve.main([str(tmp_path), "--falls", "falls_30.json", "--out", str(out)]) == 0
    text = out.read_text()
    assert "| p_s_d50 | 50 | as stored, teacher over labels | 6.00 | 1.0 % / 1.0 % (3/300; 3/4 ep.) |" in text
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
        "augmented, teacher over allowed actions, progress, anchor 1, 24 epochs, + DAgger series"
    averaged = report | {"teacher_radius": 0, "teacher_weight": 1.0, "average_last": 4,
                         "averaged": {"epochs": 4, "val": {"loss": 2.5}}, "history": [{"val": {"loss": 3.0}}]}
    assert scaling_curve.recipe(averaged).endswith("anchor 1, weights averaged over the last 4 epochs")
    assert scaling_curve.final_val_loss(averaged) == 2.5  # the saved model's, not the last epoch's
    assert scaling_curve.final_val_loss(averaged | {"averaged": None}) == 3.0
    assert scaling_curve.recipe(report | {"shards": ["s00_00000.npz", "s01_00000.npz"]}) == \
        scaling_curve.recipe(report | {"shards": ["s00_00000.npz", "s01_00000.npz", "s02_00000.npz"]})


def episodes(policy: str, n: int, seeds: list[int], sorted_runs: set[tuple[int, int]]) -> list[dict]:
    return [dataclasses.asdict(EpisodeRecord(policy, "ycb", n, seed, run, (seed, run) in sorted_runs, 10, n, False))
            for seed in seeds for run in range(4)]


def test_the_margin_is_taken_over_the_better_heuristic_on_each_models_own_scenes(tmp_path: pathlib.Path) -> None:
    start = "examples/pretrained/p_s.zip"
    (tmp_path / "p_s_d100.distill.json").write_text(json.dumps(
        {"init": start, "train_states": 100, "history": [{"epoch": 0, "val": {"loss": 9.0}}]}))
    (tmp_path / "falls.json").write_text(json.dumps({"0": cell(start, 8, 100, 20, 1),
                                                     "1": cell("runs/p_s_d100.zip", 8, 100, 5, 3)}))
    cells = tmp_path / "cells"
    cells.mkdir()
    # N = 8: the heuristics played seeds 0 and 1 (8 scenes); p_s_d100 seed 0 only, p_s both.
    # h-d sorts runs 0-1 of seed 0 and all of seed 1, h-a runs 0-3 of seed 0: on seed 0 h-a is the better (4/4),
    # on seeds 0 and 1 h-d (6/8 against h-a's 4/8).
    played = {"h-d": ([0, 1], {(0, 0), (0, 1)} | {(1, r) for r in range(4)}),
              "h-a": ([0, 1], {(0, r) for r in range(4)}),
              "p_s_d100": ([0], {(0, 0), (0, 1), (0, 2)}), "p_s": ([0, 1], {(0, 0), (1, 0)}),
              "other": ([0], set())}  # a policy off the curve: not a row
    for policy, (seeds, sorted_runs) in played.items():
        (cells / f"{policy}__ycb__N08.json").write_text(json.dumps(episodes(policy, 8, seeds, sorted_runs)))
    (cells / "p_s__ycb__N05.json").write_text(json.dumps(episodes("p_s", 5, [0], {(0, 0)})))  # no heuristic at N = 5
    data = scaling_curve.rows(*scaling_curve.load(tmp_path))
    scaling_curve.margins(data, load_cells(tmp_path), ["h-d", "h-a"])
    by = {r["policy"]: r for r in data}
    assert by["p_s_d100"]["sr_by_n"] == {8: {"sr": 75.0, "best_heuristic": 100.0, "margin": -25.0, "scenes": 4}}
    assert by["p_s"]["sr_by_n"] == {8: {"sr": 25.0, "best_heuristic": 75.0, "margin": -50.0, "scenes": 8}}
    assert by["p_s"]["mean_margin"] == -50.0
    text = scaling_curve.margin_table(data, ["h-d", "h-a"])
    assert "| p_s | 0 | 25.0 % (-50.0; 8) | -50.0 |" in text
    assert "| p_s_d100 | 100 | 75.0 % (-25.0; 4) | -25.0 |" in text
    png = tmp_path / "curve.png"
    out = tmp_path / "curve.md"
    assert scaling_curve.main([str(tmp_path), "--evaluation", str(tmp_path), "--out", str(out), "--png", str(png)]) == 0
    assert "SR N = 8 (margin over best of h-d / h-a; scenes)" in out.read_text()
    # a replicate the evaluation played but the fall measurement did not: a row of the margin table only
    (tmp_path / "p_s_d100_seed1.distill.json").write_text(json.dumps(
        {"init": start, "train_states": 100, "seed": 1, "history": [{"epoch": 0, "val": {"loss": 8.0}}]}))
    (cells / "p_s_d100_seed1__ycb__N08.json").write_text(json.dumps(episodes("p_s_d100_seed1", 8, [0], {(0, 0)})))
    assert scaling_curve.main([str(tmp_path), "--evaluation", str(tmp_path), "--out", str(out)]) == 0
    text = out.read_text()
    assert "| p_s_d100_seed1 | 100 | 25.0 % (-75.0; 4) | -75.0 |" in text
    assert "| p_s_d100_seed1 | 100 | as stored" not in text  # not in the fall table
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="no episode of the heuristic 'h-x'"):
        scaling_curve.margins(data, load_cells(tmp_path), ["h-d", "h-x"])
    for path in cells.glob("p_s*"):
        path.unlink()
    with pytest.raises(ValueError, match="no episode of a policy on the curve"):
        scaling_curve.margins(data, load_cells(tmp_path), ["h-d", "h-a"])


def test_the_trend_fits_the_margin_against_doublings_of_the_data() -> None:
    def row(states: int, margin: float, recipe: str = "r", ns: tuple[int, ...] = (5, 8)) -> dict:
        return {"policy": f"m{states}", "states": states, "recipe": recipe, "wrapped": False,
                "sr_by_n": {n: {"margin": margin} for n in ns}, "mean_margin": margin}

    rising = [row(1000, -20.0), row(2000, -15.0), row(4000, -10.0)]
    (line,) = scaling_curve.trend(rising)
    assert "r: 3 models (1000, 2000, 4000 states)" in line and "N = 5, 8" in line
    assert "+5.0 points per doubling" in line and "+0 at ~16,000 states, +15 at ~128,000 states" in line
    assert "standard error 0.0" in line and "same states" not in line
    # a replicate (the same states distilled again at another seed) is one more point, and its spread is shown
    (line,) = scaling_curve.trend(rising + [row(4000, -14.0) | {"policy": "m4000_seed1"}])
    assert "4 models (1000, 2000, 4000, 4000 states)" in line and "4000: -10.0, -14.0" in line
    # x = log2(states / 1000) = 0, 1, 2, 2; y = -20, -15, -10, -14: slope Sxy / Sxx = 10.75 / 2.75, and the
    # residuals' standard error sqrt(SSR / (4 - 2) / Sxx)
    assert "+3.9 points per doubling" in line and "standard error 1.3" in line
    falling = [row(1000, -10.0, "f"), row(2000, -12.0, "f"), row(4000, -14.0, "f")]
    (line,) = scaling_curve.trend(falling)
    assert "-2.0 points per doubling" in line and "reaches" not in line
    # two points, or models measured over other N, or a wrapped model: no line
    assert scaling_curve.trend(rising[:2]) == []
    assert scaling_curve.trend(rising[:2] + [row(4000, -10.0, ns=(8,))]) == []
    assert scaling_curve.trend(rising[:2] + [row(4000, -10.0) | {"wrapped": True}]) == []
    fewer = row(4000, -10.0)  # measured on fewer scenes than the others
    fewer["sr_by_n"][5]["scenes"] = 30
    assert scaling_curve.trend(rising[:2] + [fewer]) == []
