"""Spawning, regions and the definitions behind the reward."""

import numpy as np
import pybullet as pb
import pytest

from shelf_env import params
from shelf_env.env import ShelfSortEnv
from shelf_env.world.cabinet import Region, World, obb_corners, obbs_overlap, sample_regions
from shelf_env.world.objects import YCB_KINDS, sample_specs


@pytest.mark.parametrize("object_set", ["train", "ycb"])
def test_spawned_objects_never_overlap_rest_inside_and_start_unsorted(object_set):
    env = ShelfSortEnv(num_objects=1, object_set=object_set)
    for seed in range(12):
        n = [1, 3, 8, 14][seed % 4]
        _, info = env.reset(seed=seed, options={"num_objects": n})
        pos = env.world.positions()
        assert len(pos) == n and env.world.inside(pos).all() and env.world.at_rest().all()
        assert (pos[:, 2] < 0.2).all()  # resting on the floor, not stacked or tumbling
        assert not env.world.in_own_region(pos).all() and info["num_unsorted_initial"] >= 1
        # footprints from the simulator: no two objects' AABBs interpenetrate
        boxes = [pb.getAABB(o.uid, physicsClientId=env.client) for o in env.world.objects]
        for i in range(n):
            for j in range(i + 1, n):
                (a0, a1), (b0, b1) = boxes[i], boxes[j]
                overlap = [min(a1[k], b1[k]) - max(a0[k], b0[k]) for k in range(2)]
                # AABBs of rotated boxes may overlap a little; their true footprints must not
                if min(overlap) > 0.01:
                    pi, pj = env.world.pose(env.world.objects[i]), env.world.pose(env.world.objects[j])
                    yi = pb.getEulerFromQuaternion(pi[1])[2]
                    yj = pb.getEulerFromQuaternion(pj[1])[2]
                    ci = obb_corners(pi[0][0], pi[0][1], yi, env.world.objects[i].spec.footprint)
                    cj = obb_corners(pj[0][0], pj[0][1], yj, env.world.objects[j].spec.footprint)
                    assert not obbs_overlap(ci, cj)
    env.close()


def test_regions_fit_their_classes_and_do_not_overlap():
    rng = np.random.default_rng(0)
    for _ in range(200):
        area = rng.uniform(0, 0.03, size=3)
        regions = sample_regions(rng, area)
        assert regions is not None
        for k, r in enumerate(regions):
            assert 0 <= r.x0 < r.x1 <= params.CABINET_DEPTH and -0.3 <= r.y0 < r.y1 <= 0.3
            assert area[k] <= params.REGION_MAX_FILL * (r.x1 - r.x0) * (r.y1 - r.y0) + 1e-12
        ys = sorted((r.y0, r.y1) for r in regions)
        assert all(ys[i][1] <= ys[i + 1][0] + 1e-12 for i in range(2))
    assert sample_regions(rng, np.array([0.0, 0.0, 1.0])) is None  # cannot fit: caller redraws


def test_in_region_definition_uses_the_base_position_on_closed_rectangles():
    r = Region(0.1, 0.2, -0.05, 0.05)
    assert r.contains(0.1, -0.05) and r.contains(0.2, 0.05) and r.contains(0.15, 0.0)
    assert not r.contains(0.0999, 0.0) and not r.contains(0.15, 0.0501)
    pos = np.array([[0.15, 0.0, 0.03], [0.15, 0.0, -0.2], [0.25, 0.0, 0.03]])
    w = World.__new__(World)
    w.regions = [r]
    assert list(w.region_of(pos)) == [0, -1, -1]  # below the floor = outside = in no region
    assert list(World.inside(np.array([[0.0, 0.3, 0.0], [-0.001, 0.0, 0.05], [0.2, 0.0, 0.28]]))) == [
        True, False, False]


def test_ycb_set_has_required_kinds_and_episodes_use_at_most_three():
    assert len(YCB_KINDS) >= 8
    assert sum(s.shape not in ("box", "cylinder") for s in YCB_KINDS.values()) >= 3
    rng = np.random.default_rng(0)
    for n in (1, 3, 14):
        kinds = {s.kind for s in sample_specs("ycb", n, rng)}
        assert 1 <= len(kinds) <= min(3, n)
    with pytest.raises(ValueError, match="unknown object_set"):
        sample_specs("lego", 3, rng)


def test_wide_training_set_spans_the_test_sets_ranges_with_the_same_draws():
    from shelf_env.world import objects

    train = sample_specs("train", 400, np.random.default_rng(3))
    wide = sample_specs("train-wide", 400, np.random.default_rng(3))
    # the same draws from the generator: the same shapes in the same order, only the ranges differ
    assert [s.kind for s in train] == [s.kind for s in wide]
    assert {s.kind for s in wide} == {"cuboid", "cylinder"}
    for specs, (h_lo, h_hi), (m_lo, m_hi) in ((train, objects.TRAIN_HEIGHT, objects.TRAIN_MASS),
                                              (wide, objects.WIDE_HEIGHT, objects.WIDE_MASS)):
        heights, masses = np.array([s.height for s in specs]), np.array([s.mass for s in specs])
        assert heights.min() >= h_lo - 1e-9 and heights.max() <= h_hi + 1e-9
        assert masses.min() >= m_lo and masses.max() <= m_hi
    heights = np.array([s.height for s in wide])
    masses = np.array([s.mass for s in wide])
    ycb = list(YCB_KINDS.values())
    # the wide set reaches the test objects' extremes that the training set never does
    assert heights.max() > objects.TRAIN_HEIGHT[1] and heights.max() >= 0.9 * max(s.height for s in ycb)
    assert masses.min() < objects.TRAIN_MASS[0] and masses.min() <= 2 * min(s.mass for s in ycb)
    assert masses.max() >= 0.9 * max(s.mass for s in ycb)
    assert all(abs(v / objects.SIZE_GRID - round(v / objects.SIZE_GRID)) < 1e-6 for s in wide for v in s.size)
    assert "train-wide" in objects.OBJECT_SETS


def test_env_spawns_a_full_wide_scene():
    env = ShelfSortEnv(num_objects=14, object_set="train-wide")
    try:
        env.reset(seed=5)
        world = env.world
        assert len(world.objects) == 14
        assert World.inside(world.positions()).all()
        assert max(o.spec.height for o in world.objects) > 0.12  # taller than any training object
    finally:
        env.close()
