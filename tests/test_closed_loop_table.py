"""research/closed_loop_table.py: issue 13's table counts sorted episodes and falls per folder and
compares each folder with the first (the open loop)."""

import json
import pathlib

from research import closed_loop_table
from shelf_env.evaluation import protocol as ev


def write_folder(out: pathlib.Path, outcomes: dict[int, list[tuple[bool, bool]]], conditions=None) -> pathlib.Path:
    for n, episodes in outcomes.items():
        records = [ev.EpisodeRecord("h-d", "ycb", n, 0, run, success, 5, n, fell, failure="fell" if fell else "")
                   for run, (success, fell) in enumerate(episodes)]
        path = ev.cell_path(out, "h-d", "ycb", n, 0, len(records))
        path.parent.mkdir(parents=True, exist_ok=True)
        ev.save_cell(path, records)
    if conditions is not None:
        (out / "conditions.json").write_text(json.dumps(conditions))
    return out


def test_table_counts_and_compares_with_the_open_loop(tmp_path, capsys):
    off = write_folder(tmp_path / "off", {3: [(True, False), (False, True)], 8: [(False, True)] * 4})
    on = write_folder(tmp_path / "on", {3: [(True, False), (True, False)], 8: [(True, False)] + [(False, True)] * 3},
                      {"closed_loop": {"sustain": 2}})
    table = tmp_path / "table.md"
    assert closed_loop_table.main([str(off), str(on), "--out", str(table)]) == 0
    text = table.read_text()
    assert text == capsys.readouterr().out
    assert "| off | h-d | 1 / 1 | 0 / 4 | 4 (+0 %) | 1 (+0) |" in text
    assert "| on | h-d | 2 / 0 | 1 / 3 | 3 (-25 %) | 2 (+1) |" in text
    assert '- `on`: {"sustain": 2}' in text and '- `off`: "open loop"' in text
    # a policy evaluated in one folder only has no row in the other
    records = [ev.EpisodeRecord("h-a", "ycb", 3, 0, 0, True, 2, 3, False)]
    ev.save_cell(ev.cell_path(off, "h-a", "ycb", 3, 0, 1), records)
    assert closed_loop_table.main([str(off), str(on)]) == 0
    text = capsys.readouterr().out
    assert "| off | h-a | 1 / 0 | - | - | 1 (+0) |" in text and "| on | h-a |" not in text


def test_a_grid_still_being_evaluated_is_not_compared(tmp_path, capsys):
    off = write_folder(tmp_path / "off", {3: [(True, False)] * 2, 8: [(False, True)] * 2})
    on = write_folder(tmp_path / "on", {3: [(True, False)] * 2})  # N = 8 not evaluated yet
    assert closed_loop_table.main([str(off), str(on)]) == 0
    assert "| on | h-d | 2 / 0 | - | - | 2 (+0) |" in capsys.readouterr().out
    fewer = write_folder(tmp_path / "fewer", {3: [(True, False)], 8: [(False, False)] * 2})  # 1 run of 2 at N = 3
    assert closed_loop_table.main([str(off), str(fewer)]) == 0
    assert "| fewer | h-d | 1 / 0 | 0 / 0 | 0 (-100 %) | - |" in capsys.readouterr().out


def test_a_folder_without_cells_is_named(tmp_path, capsys):
    assert closed_loop_table.main([str(tmp_path / "nothing")]) == 2
    assert "nothing/cells has no evaluation cells" in capsys.readouterr().err


def test_policies_and_seeds_keep_only_those_records(tmp_path, capsys):
    off = write_folder(tmp_path / "off", {8: [(False, True)] * 4})
    on = write_folder(tmp_path / "on", {8: [(True, False)] * 4})
    # seed 1 of the open loop only (the closed loop was run on seed 0): left out with --seeds 0
    ev.save_cell(ev.cell_path(off, "h-d", "ycb", 8, 1, 2),
                 [ev.EpisodeRecord("h-d", "ycb", 8, 1, run, False, 5, 8, True) for run in range(2)])
    ev.save_cell(ev.cell_path(on, "h-a", "ycb", 8, 0, 1), [ev.EpisodeRecord("h-a", "ycb", 8, 0, 0, True, 2, 8, False)])
    assert closed_loop_table.main([str(off), str(on)]) == 0
    assert "| off | h-d | 0 / 6 | 6 (+0 %) | 0 (+0) |" in capsys.readouterr().out
    assert closed_loop_table.main([str(off), str(on), "--seeds", "0", "--policies", "h-d"]) == 0
    text = capsys.readouterr().out
    assert "with `off`; policies h-d only; seeds 0 only." in text
    assert "| off | h-d | 0 / 4 | 4 (+0 %) | 0 (+0) |" in text and "| on | h-d | 4 / 0 | 0 (-100 %) | 0 (+0) |" in text
    assert "h-a" not in text.split("Watches")[0]
