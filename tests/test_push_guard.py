"""research/push_guard.py: ``+push-guard`` masks the pushes whose blade meets an object that looks sorted (the env's
mask geometry on the sorted-looking cells), ``+pick-first`` every push while a pick is allowed; both stand aside
when nothing allowed would be left, never touch a pick, and parse innermost under the shipped wrappers."""

import numpy as np
import pytest
from pixel_envs import ScoresPolicy
from test_pick_guard import crafted, flat

from research.push_guard import PushGuard, sorted_pushes
from shelf_env import policies
from shelf_env.actions import occupancy_masks
from shelf_env.baselines.heuristics import ObservationView

H, W, MAPS = 40, 60, 3
NAMES = ("pick", "push_left", "push_right")


def scores():
    """Best: push-left at (33, 12), into object A (sorted, rows 31-35, cols 5-9); then push-left at (7, 47), into
    object B (unsorted, rows 5-9, cols 40-44); then a pick of B."""
    s = np.zeros(MAPS * H * W)
    s[flat(1, 33, 12)] = 3.0
    s[flat(1, 7, 47)] = 2.0
    s[flat(0, 7, 42)] = 1.0
    return s


def test_the_banned_pushes_are_the_env_masks_geometry_on_the_sorted_looking_cells():
    obs = crafted()
    cells = ObservationView.from_observation(obs, margin_cells=0).sorted_cells
    assert cells[33, 7] and not cells[7, 42]  # A looks sorted, B does not
    banned = sorted_pushes(obs, NAMES).reshape(MAPS, H, W)
    expected = occupancy_masks(cells, 0.01, NAMES).reshape(MAPS, H, W)
    assert not banned[0].any()  # never a pick
    assert np.array_equal(banned[1:], expected[1:]) and banned[1:].any()
    assert banned[1, 33, 12] and banned[2, 33, 0] and not banned[1, 7, 47] and not banned[1, 33, 20]
    unsorted = obs.copy()
    unsorted[:3, 28:40, 0:20] = 255  # no region tint: nothing looks sorted, nothing is banned
    unsorted[:3, 31:36, 5:10] = obs[:3, 31:36, 5:10]
    assert not sorted_pushes(unsorted, NAMES).any()


def test_push_guard_masks_the_push_at_a_sorted_object_and_stands_aside_when_nothing_else_is_allowed():
    obs = crafted()
    guard = PushGuard(ScoresPolicy(scores(), (4, H, W)), NAMES, H, W)
    assert int(guard.predict(obs)[0]) == flat(1, 7, 47)  # the push into A is masked, the push into B is not
    assert guard.stats == {"guarded": 1, "unguarded": 0}
    only = np.zeros(MAPS * H * W, bool)
    only[flat(1, 33, 12)] = True
    assert int(guard.predict(obs, action_masks=only)[0]) == flat(1, 33, 12)
    assert guard.stats == {"guarded": 2, "unguarded": 1}
    masks = np.ones(MAPS * H * W, bool)
    masks[flat(1, 7, 47)] = False  # the caller's masks still hold: the pick of B is next
    assert int(guard.predict(obs, action_masks=masks)[0]) == flat(0, 7, 42)


def test_pick_first_masks_every_push_while_a_pick_is_allowed():
    obs = crafted()
    guard = PushGuard(ScoresPolicy(scores(), (4, H, W)), NAMES, H, W, mode="all")
    assert int(guard.predict(obs)[0]) == flat(0, 7, 42)
    pushes_only = np.ones(MAPS * H * W, bool)
    pushes_only[:H * W] = False  # no pick allowed: nothing to mask, the best push
    assert int(guard.predict(obs, action_masks=pushes_only)[0]) == flat(1, 33, 12)
    assert guard.stats == {"guarded": 1, "unguarded": 0}


def test_bad_input_and_the_registry():
    with pytest.raises(ValueError, match="mode"):
        PushGuard(ScoresPolicy(scores(), (4, H, W)), NAMES, H, W, mode="some")
    with pytest.raises(ValueError, match="push maps"):
        PushGuard(ScoresPolicy(np.zeros(H * W), (4, H, W)), ("pick",), H, W)
    with pytest.raises(ValueError, match="shape"):
        PushGuard(ScoresPolicy(scores(), (4, H, W)), NAMES, H, W).predict(np.zeros((1, 4, H, W)))
    assert policies.policy_wrappers("m.zip+push-guard+geometry-filter+pick-guard+loop-breaker") == (
        "m.zip", ("+push-guard", "+geometry-filter", "+pick-guard", "+loop-breaker"))
    assert policies.policy_wrappers("m.zip+pick-first+loop-breaker") == ("m.zip", ("+pick-first", "+loop-breaker"))


def test_print_or_write_prints_one_newline_or_writes_the_file(tmp_path, capsys):
    from research import print_or_write

    print_or_write("a table\n", None)
    print_or_write("a page", None)
    assert capsys.readouterr().out == "a table\na page\n"
    print_or_write("a table\n", tmp_path / "t.md")
    assert (tmp_path / "t.md").read_text() == "a table\n" and capsys.readouterr().out == ""


def test_table_command_prints_writes_or_refuses(tmp_path, capsys):
    from research import table_command

    assert table_command(lambda: "a table\n", None) == 0 and capsys.readouterr().out == "a table\n"
    assert table_command(lambda: "a table\n", tmp_path / "t.md") == 0 and (tmp_path / "t.md").read_text() == "a table\n"

    def bad() -> str:
        raise ValueError("no shards of series 's09'")

    assert table_command(bad, tmp_path / "u.md") == 2 and not (tmp_path / "u.md").exists()
    assert capsys.readouterr().err == "error: no shards of series 's09'\n"
