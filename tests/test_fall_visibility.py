"""The privileged top-down view (`shelf_env.privileged.topdown`) and the replay that pairs it with the teacher
dataset's camera observations (`research.fall_visibility`): the view shows exactly what stands where, with
nothing occluded; a replay reproduces the stored states; the comparison trains both views on the same labels."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch as th
from conftest import REGIONS, box

from research import fall_risk as fr
from research import fall_visibility as fv
from shelf_env import params
from shelf_env.camera.heightmap import CLASS_RGB, FREE, OCCLUDED_RGB, REGION_RGB
from shelf_env.privileged import dataset
from shelf_env.privileged.topdown import topdown_observation, topdown_semantic


def test_a_box_seen_from_above_has_its_footprint_height_and_class(env):
    """A 6 x 6 x 8 cm box at the cabinet's centre: its 12 x 12 cells (5 mm) at 8 cm, in its class colour, the
    rest of the floor free; a tall box in front hides nothing from above, while the camera sees grey behind it."""
    obs, _ = env.set_scene([(box(0.06, 0.06, 0.08), 1, 0.20, 0.0, 0.0), (box(0.04, 0.20, 0.20), 2, 0.06, 0.0, 0.0)],
                           REGIONS)
    cell_uid, height = topdown_semantic(env)
    first, tall = (o.uid for o in env.world.objects)
    assert abs(int((cell_uid == first).sum()) - 144) <= 26  # 12 x 12 cells, give or take a row and a column
    assert np.allclose(height[cell_uid == first], 0.08, atol=0.003)
    assert np.allclose(height[cell_uid == tall], 0.20, atol=0.003)
    assert (height[cell_uid == FREE] == 0).all() and set(np.unique(cell_uid)) == {FREE, first, tall}
    top = topdown_observation(env)
    assert top.shape == obs.shape and top.dtype == np.uint8
    assert (top[:3, cell_uid == first].T == CLASS_RGB[1]).all()
    assert np.abs(top[3, cell_uid == first].astype(int) - round(0.08 / params.CABINET_HEIGHT * 255)).max() <= 1
    grey = lambda o: (o[:3] == OCCLUDED_RGB[:, None, None]).all(0)  # noqa: E731
    assert grey(obs).sum() > 100 and not grey(top).any()  # the camera's shadow behind the tall box; none from above
    rows, cols = np.nonzero(cell_uid == first)
    assert grey(obs)[rows, cols].mean() > 0.9  # the first box stands in that shadow


def test_the_view_agrees_with_the_camera_where_the_camera_sees(env):
    """On a random scene of six objects: no occluded cell, every object seen, and where the camera sees
    an object or free floor the top-down view says the same class or free (up to the camera's side faces)."""
    env.set_num_objects(6)
    obs, _ = env.reset(seed=3)
    cell_uid, _ = topdown_semantic(env)
    assert {o.uid for o in env.world.objects} <= set(np.unique(cell_uid).tolist())
    top = topdown_observation(env)

    def classes(o):
        out = np.full(o.shape[1:], -1)
        for k, colour in enumerate(CLASS_RGB):
            out[(o[:3] == colour[:, None, None]).all(0)] = k
        return out

    def floor(o):
        return np.any([(o[:3] == np.asarray(c)[:, None, None]).all(0) for c in (255 * np.ones(3), *REGION_RGB)], 0)

    cam, seen = classes(obs), classes(top)
    both = (cam >= 0) & (seen >= 0)
    assert (cam[both] == seen[both]).all() and both.sum() > 0.8 * (cam >= 0).sum()
    assert floor(top)[floor(obs)].mean() > 0.99
    assert not (top[:3] == OCCLUDED_RGB[:, None, None]).all(0).any()


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    out = tmp_path_factory.mktemp("teacher")
    assert dataset.collect(out, hours=1.0, ns=(2,), model_path=None, episodes_per_shard=2, max_shards=2,
                           max_probes=6) == 2
    return out


def test_a_replay_reproduces_the_stored_states_and_resumes(shards, tmp_path):
    shard = dataset.load_dataset(shards)[0]
    every = fv.replay_shard(shard, np.arange(shard.num_states))
    assert every["match"].all() and every["topdown"].shape == shard.arrays["obs"].shape
    some = fv.replay_shard(shard, np.array([1, shard.num_states - 1]))
    assert np.array_equal(some["topdown"], every["topdown"][[1, -1]]) and some["match"].all()
    counts = fv.replay(shards, tmp_path / "r", 0.25, None, None)
    assert counts == {"written": 2, "skipped": 0, "states": sum(s.num_states for s in dataset.load_dataset(shards))}
    assert fv.replay(shards, tmp_path / "r", 0.25, None, None)["skipped"] == 2  # resumes: nothing redone
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["s00_00000.npz", "s00_00001.npz"]
    with pytest.raises(ValueError, match="need 0 <= part < parts"):
        fv.replay(shards, tmp_path / "r", 0.25, None, None, part=2, parts=2)


def test_the_comparison_trains_both_views_on_the_same_labels(shards, tmp_path):
    fv.replay(shards, tmp_path / "r", 0.25, None, None)
    report = fv.compare(shards, tmp_path / "r", "examples/pretrained/v1/p_s.zip", tmp_path / "c.json", 0.25, None,
                        None, epochs=1, models=tmp_path)
    train, val = fr.load_splits(shards, 0.25)
    assert report["train_states"] == len(train.obs) and report["val_states"] == len(val.obs)
    assert report["train_dropped"] == report["val_dropped"] == 0 and report["val_labels"] == len(val.label)
    assert set(report["views"]) == {"camera", "topdown"}
    on_disk = json.loads((tmp_path / "c.json").read_text())
    assert json.dumps(on_disk, sort_keys=True) == json.dumps(report, sort_keys=True)  # (NaN AUCs: no held-out fall)
    assert report["offline"]["labels"] == len(val.label)
    for view in ("camera", "topdown"):
        assert fr.FallRiskModel.load(tmp_path / f"{view}.fall_risk.pt").info["view"] == view
    assert report["init"] == "examples/pretrained/v1/p_s.zip"
    scratch = fv.compare(shards, tmp_path / "r", "examples/pretrained/v1/p_s.zip", tmp_path / "s.json", 0.25, None,
                         None, epochs=1, init=None)
    assert scratch["init"] is None and scratch["val_labels"] == report["val_labels"]
    (tmp_path / "r" / "s00_00001.npz").unlink()
    with pytest.raises(ValueError, match="no top-down replay of s00_00001.npz"):
        fv.compare(shards, tmp_path / "r", "examples/pretrained/v1/p_s.zip", tmp_path / "d.json", 0.25, None, None)
    assert not (tmp_path / "d.json").exists()


def test_a_subset_keeps_its_states_labels_in_step():
    split = fr.Split(th.arange(4 * 2).reshape(4, 2).to(th.uint8), th.tensor([0, 1, 1, 3, 2]),
                     th.tensor([5, 6, 7, 8, 9]), th.tensor([0.0, 1.0, 0.0, 1.0, 1.0]), np.array([3, 4, 5, 6]),
                     np.array([1, 0, 1, 0, 0]))
    kept = fv.subset(split, np.array([1, 3]))
    assert kept.obs.tolist() == [[2, 3], [6, 7]] and kept.state.tolist() == [0, 0, 1]
    assert kept.cell.tolist() == [6, 7, 8] and kept.label.tolist() == [1.0, 0.0, 1.0]
    assert kept.objects.tolist() == [4, 6] and kept.sorted_change.tolist() == [0, 1, 0]
    other = fv.subset(split, np.array([1, 3]), th.zeros(4, 2, dtype=th.uint8) + 9)
    assert other.obs.tolist() == [[9, 9], [9, 9]] and other.state.tolist() == kept.state.tolist()


def test_neighbour_agreement_reads_the_nearest_pick_of_the_same_object():
    """Two objects (blobs of one class colour) and a cell on none: each pick is predicted by the nearest other
    labelled pick of its own object (the mean where several are equally near), counted at each distance."""
    obs = np.full((2, 4, 6, 8), 255, np.uint8)
    obs[0, :3, 1, 1:5] = np.asarray(CLASS_RGB[0])[:, None]  # object A: row 1, columns 1-4
    obs[0, :3, 4, 1:3] = np.asarray(CLASS_RGB[0])[:, None]  # object B: row 4, columns 1-2
    obs[1, :3, 2, 2:5] = np.asarray(CLASS_RGB[2])[:, None]  # the second state's object: row 2, columns 2-4
    picks = [(0, 1, 1, 1), (0, 1, 2, 1), (0, 1, 4, 0), (0, 4, 1, 0), (0, 4, 2, 0), (0, 5, 7, 1),
             (1, 2, 2, 1), (1, 2, 3, 0), (1, 2, 4, 0)]
    state, row, col, label = (np.array(v) for v in zip(*picks))
    split = fr.Split(th.as_tensor(obs), th.as_tensor(state), th.as_tensor(row * 8 + col),
                     th.as_tensor(label, dtype=th.float32))
    got = fv.neighbour_agreement(split)
    assert got["labels"] == 9 and got["states"] == 2
    one, two = got["by_distance"]["1"], got["by_distance"]["2"]
    # within one cell: A's first two (1, 1), B's two (0, 0), and the second state's three: (2, 2) -> 0,
    # (2, 3) -> the mean of 1 and 0, (2, 4) -> 0
    assert one["labels"] == 7 and one["invalid"] == pytest.approx(3 / 7)
    assert one["differ"] == pytest.approx((0 + 0 + 0 + 0 + 1 + 0.5 + 0) / 7)
    assert one["auc"] == pytest.approx(fr.auc(np.array([1, 1, 0, 0, 1, 0, 0]), np.array([1, 1, 0, 0, 0, 0.5, 0])))
    # within two: also A's third pick, whose nearest (two cells away) fell while it did not
    assert two["labels"] == 8 and two["differ"] == pytest.approx((1 + 0.5 + 1) / 8)
    assert got["by_distance"]["3"]["labels"] == 8  # the pick on no object has no neighbour at any distance
