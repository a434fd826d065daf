"""research/planner_probe.py: per N, each policy's scenes sorted and dropped over exactly the planner's scenes,
the planner's env actions per decision, and the per-scene table."""

import pathlib

from research import planner_probe
from shelf_env.evaluation.protocol import EpisodeRecord, cell_path, save_cell


def record(policy: str, n: int, run: int, success: bool, fell: bool = False, actions: int = 10,
           stats: dict[str, int] | None = None) -> EpisodeRecord:
    return EpisodeRecord(policy, "ycb", n, 0, run, success, actions, n, fell, failure="" if success else
                         ("fell" if fell else "timeout"), policy_stats=stats or {})


def test_the_summary_counts_only_the_planners_scenes(tmp_path: pathlib.Path) -> None:
    mine, theirs = tmp_path / "planner", tmp_path / "models"
    stats = {"decisions": 4, "actions": 30}
    save_cell(cell_path(mine, "h-d-planner", "ycb", 5, 0, 2),
              [record("h-d-planner", 5, r, True, stats=stats) for r in range(2)])
    save_cell(cell_path(mine, "h-d-planner", "ycb", 8, 0, 1), [record("h-d-planner", 8, 0, False, stats=stats)])
    # h-d played 3 scenes at N = 5 (the third is not the planner's) and none at N = 8; p_s played all of them
    save_cell(cell_path(theirs, "h-d", "ycb", 5, 0, 3),
              [record("h-d", 5, 0, True), record("h-d", 5, 1, False, fell=True), record("h-d", 5, 2, True)])
    save_cell(cell_path(theirs, "p_s", "ycb", 5, 0, 2), [record("p_s", 5, r, False, fell=True) for r in range(2)])
    save_cell(cell_path(theirs, "p_s", "ycb", 8, 0, 1), [record("p_s", 8, 0, True)])
    out = tmp_path / "report.md"
    assert planner_probe.main([str(mine), "--against", str(theirs), "--out", str(out)]) == 0
    text = out.read_text()
    assert ("| N | scenes | h-d-planner | h-d | p_s | planner env actions per decision | margin over the best of "
            "h-d, h-a (points) |") in text
    # h-a played none of the scenes: no margin anywhere
    assert "| 5 | 2 | 2 / 2 (fell 0) | 1 / 2 (fell 1) | 0 / 2 (fell 2) | 7.5 | - |" in text
    assert "| 8 | 1 | 0 / 1 (fell 0) | - | 1 / 1 (fell 0) | 7.5 | - |" in text  # h-d lacks the scene: no count
    assert "averaged over the 0 N measured (): none." in text
    assert "| 5 | 0 | 1 | sorted in 10 | fell in 10 | fell in 10 |" in text
    assert "The planner spent 7.5 env actions per decision (12 decisions)." in text
    assert planner_probe.main([str(mine), "--against", str(theirs), "--out", str(out), "--policies", "p_s",
                               "--heuristics"]) == 0
    assert "| 5 | 2 | 2 / 2 (fell 0) | 0 / 2 (fell 2) | 7.5 |\n" in out.read_text()
    assert "margin" not in out.read_text()
    # the margin: the planner's SR minus the better heuristic's over the same scenes, per N and averaged
    assert planner_probe.main([str(mine), "--against", str(theirs), "--out", str(out), "--heuristics", "h-d",
                               "p_s"]) == 0
    text = out.read_text()
    assert "| 5 | 2 | 2 / 2 (fell 0) | 1 / 2 (fell 1) | 0 / 2 (fell 2) | 7.5 | +50.0 |" in text  # 100 - max(50, 0)
    assert "| 8 | 1 | 0 / 1 (fell 0) | - | 1 / 1 (fell 0) | 7.5 | - |" in text
    assert "h-d-planner's margin over the best of h-d, p_s averaged over the 1 N measured (5): +50.0 points." in text
    save_cell(cell_path(theirs, "h-d", "ycb", 8, 0, 1), [record("h-d", 8, 0, False, fell=True)])
    assert planner_probe.main([str(mine), "--against", str(theirs), "--out", str(out), "--heuristics", "h-d",
                               "p_s"]) == 0
    text = out.read_text()
    assert "| 7.5 | -100.0 |" in text  # N = 8: 0 - max(0, 100)
    assert "averaged over the 2 N measured (5, 8): -25.0 points." in text


def test_a_folder_without_cells_is_one_line(tmp_path: pathlib.Path, capsys) -> None:
    assert planner_probe.main([str(tmp_path), "--against", str(tmp_path), "--out", str(tmp_path / "r.md")]) == 2
    assert "has no evaluation cells" in capsys.readouterr().err and not (tmp_path / "r.md").exists()


def test_a_policy_that_did_not_play_the_scenes_is_refused(tmp_path: pathlib.Path, capsys) -> None:
    save_cell(cell_path(tmp_path / "a", "h-d-planner", "ycb", 5, 0, 1), [record("h-d-planner", 5, 0, True)])
    save_cell(cell_path(tmp_path / "b", "h-d", "ycb", 5, 0, 1), [record("h-d", 5, 0, True)])
    out = tmp_path / "r.md"
    assert planner_probe.main([str(tmp_path / "a"), "--against", str(tmp_path / "b"), "--out", str(out),
                               "--policies", "h-d", "p_s"]) == 2
    assert "no record of ['p_s'] on the planner's scenes (policies there: ['h-d'])" in capsys.readouterr().err
    assert not out.exists()
