"""research/edge_guard.py: ``+edge-guard`` reads as borderline the objects that do not look sorted but lie within
their region widened to its known width (columns) and a cell of slack (rows); it masks their picks while a pick of
another object is allowed and stands aside otherwise; ``stats`` counts a series' greedy picks by outcome and
reading; ``live`` judges a policy's picks by the env's rule."""

import numpy as np
import pytest
from pixel_envs import ScoresPolicy
from test_pick_guard import paint

from research import edge_guard
from research.edge_guard import EdgeGuard, borderline_cells
from shelf_env import policies
from shelf_env.baselines.heuristics import ObservationView
from shelf_env.camera.heightmap import CLASS_RGB, REGION_RGB

H, W, MAPS = 40, 60, 3
NAMES = ("pick", "push_left", "push_right")


def crafted():
    """1 cm cells. Class 0's region: rows 20-35, cols 30-47 (18 cells, the full width); A (class 0) inside it (looks
    sorted); D (class 0) over its front edge, centroid row 36 (one cell out: borderline). Class 1's region: rows
    5-15, cols 0-17, whose left four columns E (class 1) hides over the region's whole depth, so the visible tint is
    14 columns wide and E's centroid (col 1.5) lies left of it (borderline: the width completes it). F (class 1) at
    rows 30-34, cols 50-54, far from its region (clear); G (class 0) at rows 37-39, cols 10-14, far from its region
    and two rows beyond its depth (clear)."""
    obs = np.full((4, H, W), 255, np.uint8)
    obs[3] = 0
    paint(obs, slice(20, 36), slice(30, 48), REGION_RGB[0], 0.0)
    paint(obs, slice(5, 16), slice(0, 18), REGION_RGB[1], 0.0)
    paint(obs, slice(24, 28), slice(36, 40), CLASS_RGB[0])  # A
    paint(obs, slice(35, 38), slice(40, 44), CLASS_RGB[0])  # D
    paint(obs, slice(5, 16), slice(0, 4), CLASS_RGB[1])  # E
    paint(obs, slice(30, 35), slice(50, 55), CLASS_RGB[1])  # F
    paint(obs, slice(37, 40), slice(10, 15), CLASS_RGB[0])  # G
    return obs


def flat(m, row, col):
    return m * H * W + row * W + col


def test_borderline_objects_are_the_edge_and_the_hidden_tint_not_the_sorted_or_the_clear():
    obs = crafted()
    view = ObservationView.from_observation(obs, margin_cells=0)
    assert view.regions[1] == (5, 15, 4, 17)  # E hides the region's left columns
    assert view.sorted_cells[25, 37] and not view.sorted_cells[36, 41] and not view.sorted_cells[10, 1]
    edge = borderline_cells(obs)
    assert edge[36, 41] and edge[10, 1]  # D (the edge) and E (the hidden tint), every cell of each
    assert edge.sum() == 3 * 4 + 11 * 4
    assert not edge[25, 37] and not edge[32, 52] and not edge[38, 12]  # A is the pick guard's; F and G are clear
    tight = borderline_cells(obs, row_slack=0.5)  # D's centroid is a full row out
    assert not tight[36, 41] and tight[10, 1]
    with pytest.raises(ValueError, match=r"\(4, H, W\)"):
        borderline_cells(obs[None])


def scores():
    """Best: a pick of D (borderline), then of E (borderline), then of F (clear), then a push at (20, 5)."""
    s = np.zeros(MAPS * H * W)
    s[flat(0, 36, 41)] = 4.0
    s[flat(0, 10, 1)] = 3.0
    s[flat(0, 32, 52)] = 2.0
    s[flat(1, 20, 5)] = 1.0
    return s


def test_the_guard_defers_borderline_picks_until_only_they_are_left():
    obs = crafted()
    guard = EdgeGuard(ScoresPolicy(scores(), (4, H, W)), NAMES, H, W)
    assert int(guard.predict(obs)[0]) == flat(0, 32, 52)  # D and E deferred: F first
    assert guard.stats == {"deferred": 1, "released": 0}
    masks = np.ones(MAPS * H * W, bool)
    masks[:H * W] = False
    masks[flat(0, 10, 1)] = True  # F picked (masked by the caller); of the picks only E's cell is left
    assert int(guard.predict(obs, action_masks=masks)[0]) == flat(0, 10, 1)  # E's turn, ahead of the push
    assert guard.stats == {"deferred": 1, "released": 1}
    pushes = np.zeros(MAPS * H * W, bool)
    pushes[flat(1, 20, 5)] = True  # no pick allowed at all: the push, and nothing counted
    assert int(guard.predict(obs, action_masks=pushes)[0]) == flat(1, 20, 5)
    assert guard.stats == {"deferred": 1, "released": 1}
    with pytest.raises(ValueError, match="shape"):
        guard.predict(np.zeros((1, 4, H, W)))
    assert policies.policy_wrappers("m.zip+edge-guard+geometry-filter+pick-guard+loop-breaker") == (
        "m.zip", ("+edge-guard", "+geometry-filter", "+pick-guard", "+loop-breaker"))


def shard(folder):
    """One shard of one episode, two states of `crafted`: a greedy pick of D that changed nothing, a greedy pick of F
    that sorted it, a greedy pick of E that dropped an object, one greedy pick off every object and one pick of D by
    another source (neither counted)."""
    from shelf_env.privileged import dataset

    folder.mkdir(parents=True)
    ep = dataset.Episode()
    obs = crafted()
    greedy, other = dataset.SOURCES.index("greedy"), dataset.SOURCES.index("object")
    labels = [(0, flat(0, 36, 41), True, 0, greedy), (0, flat(0, 2, 30), True, 0, greedy),
              (1, flat(0, 32, 52), True, 1, greedy), (1, flat(0, 10, 1), False, 0, greedy),
              (1, flat(0, 36, 42), True, 1, other)]
    for state, action, valid, dsorted, source in labels:
        for key, v in zip(dataset.LABEL_KEYS, (state, action, valid, not valid, False, dsorted, source)):
            ep.labels[key].append(v)
    for t in range(2):
        ep.obs.append(obs)
        for key, v in zip(dataset.EPISODE_STATE_KEYS, (t, 0, np.nan, 0)):
            ep.states[key].append(v)
    layout = {"obs_shape": [4, H, W], "pixel_size": 0.01, "map_names": list(NAMES)}
    meta = {"format": dataset.FORMAT, "dynamics_version": dataset.DYNAMICS_VERSION, "layout": layout, "series": 5,
            "shard": 0, "episodes": [{"num_objects": 5}]}
    dataset.save_shard(folder / "s05_00000.npz", meta, [ep], layout["obs_shape"])


def test_stats_count_the_greedy_picks_by_outcome_and_reading(tmp_path, capsys):
    shard(tmp_path / "data")
    assert edge_guard.greedy_stats(tmp_path / "data", "s05:1") == {
        "same": 1, "same_borderline": 1, "sorted": 1, "invalid": 1, "invalid_borderline": 1}
    out = tmp_path / "series5.md"
    assert edge_guard.main(["stats", str(tmp_path / "data"), "--max-shards", "s05:1", "--out", str(out)]) == 0
    table = out.read_text()
    assert "| same | 1 | 33.3 % | 1 | 100.0 % |" in table and "| sorted | 1 | 33.3 % | 0 | 0.0 % |" in table
    assert edge_guard.main(["stats", str(tmp_path / "data"), "--max-shards", "s05:2"]) == 2
    assert "holds 1" in capsys.readouterr().err


def test_live_judges_each_pick_by_the_env_s_rule(capsys):
    counts = edge_guard.live_counts("h-d", 3, 1, 7000, "ycb")
    assert counts and sum(counts.values()) >= 1
    kinds = {"unsorted->sorted", "sorted->sorted", "unsorted->unsorted", "sorted->unsorted", "invalid"}
    for key in counts:
        kind, reading = key.split("|")
        assert kind in kinds and reading in {"clear", "borderline", "looked_sorted"}
        assert reading != "looked_sorted"  # H-d never picks an object that looks sorted
    assert edge_guard.main(["live", "--policy", "h-d", "--n", "0"]) == 2
    assert "--n" in capsys.readouterr().err
