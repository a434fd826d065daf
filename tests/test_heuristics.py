"""H-d, H-a and the random floor on crafted observations (no physics needed to decide)."""

import gymnasium as gym
import numpy as np
import pytest
from pixel_envs import FindTheSquareEnv

import shelf_env  # noqa: F401
from shelf_env.actions import ActionCodec
from shelf_env.baselines.heuristics import AccessibilityHeuristic, DistanceHeuristic, RandomPolicy, label_blobs
from shelf_env.camera.heightmap import CLASS_RGB, FREE_RGB, REGION_RGB

H, W = 80, 120
CODEC = ActionCodec.for_primitives(("pick", "push"), 0.005)


@pytest.fixture(scope="module")
def envs():
    ps = gym.make("ShelfSort-v0")
    s = gym.make("ShelfSort-v0", primitives=("pick",))
    yield ps, s
    ps.close()
    s.close()


def observation(objects, regions=((0, 79, 0, 35), (0, 79, 42, 77), (0, 79, 84, 119))) -> np.ndarray:
    """Recoloured map: white floor, tinted regions (rows/cols inclusive), class-coloured blobs."""
    rgb = np.empty((H, W, 3), dtype=np.uint8)
    rgb[:] = FREE_RGB
    for k, (r0, r1, c0, c1) in enumerate(regions):
        rgb[r0:r1 + 1, c0:c1 + 1] = REGION_RGB[k]
    height = np.zeros((H, W), dtype=np.uint8)
    for cls, r0, r1, c0, c1 in objects:
        rgb[r0:r1 + 1, c0:c1 + 1] = CLASS_RGB[cls]
        height[r0:r1 + 1, c0:c1 + 1] = 60
    return np.concatenate([rgb.transpose(2, 0, 1), height[None]])


def cell(action: int) -> tuple[int, int, int]:
    name, row, col = CODEC.decode(int(action))
    return CODEC.map_index(name), row, col


def test_h_d_picks_the_object_farthest_from_its_region_away_from_its_edge(envs):
    # class 0's region is the left strip (cols 0..35); one green box just right of it, one far right
    obs = observation([(0, 30, 41, 45, 56), (0, 30, 41, 100, 111)])
    m, row, col = cell(DistanceHeuristic(envs[0]).predict(obs)[0])
    assert m == 0 and 30 <= row <= 41 and 100 <= col <= 111
    assert 30 + 3 <= row <= 41 - 3 and 100 + 3 <= col <= 111 - 3  # a cup radius inside the blob


def test_h_a_prefers_the_front_one_of_equally_misplaced_objects(envs):
    # two green boxes equally far from the left strip: one at the back, one at the front
    obs = observation([(0, 5, 16, 90, 101), (0, 60, 71, 90, 101)])
    _, row, _ = cell(AccessibilityHeuristic(envs[0]).predict(obs)[0])
    assert row >= 60
    _, row_d, _ = cell(DistanceHeuristic(envs[0]).predict(obs)[0])  # H-d has no preference: ties -> front
    assert row_d >= 60


def test_h_a_never_picks_a_sorted_object_while_one_is_misplaced(envs):
    # a blue box sorted at the very front, a yellow one misplaced at the back
    obs = observation([(2, 66, 77, 95, 106), (1, 2, 13, 10, 21)])
    _, row, col = cell(AccessibilityHeuristic(envs[0]).predict(obs)[0])
    assert row <= 13 and col <= 21


def test_h_a_uncovers_when_everything_visible_is_sorted(envs):
    obs = observation([(0, 10, 21, 5, 16), (2, 60, 71, 95, 106)])
    _, row, col = cell(AccessibilityHeuristic(envs[0]).predict(obs)[0])
    assert row >= 60 and col >= 95


def test_label_blobs_separates_objects_and_classes():
    labels = np.full((6, 8), -1)
    labels[0:2, 0:2] = 0  # blob A
    labels[0:2, 5:8] = 0  # blob B: same class, not touching A
    labels[3:6, 0] = 1  # an L of class 1 ...
    labels[5, 0:4] = 1
    labels[3:5, 1:3] = 2  # ... touching a class-2 square, which stays separate
    blobs = label_blobs(labels)
    assert blobs.max() == 3 and (blobs[labels < 0] == -1).all()
    assert len(np.unique(blobs[0:2, 0:2])) == 1 and blobs[0, 0] != blobs[0, 5]
    assert len(np.unique(blobs[labels == 1])) == 1 and blobs[5, 3] == blobs[3, 0]
    assert blobs[3, 1] != blobs[3, 0] and len(np.unique(blobs[labels == 2])) == 1


def test_heuristics_skip_sorted_objects_whose_edge_pokes_out_of_their_region(envs):
    # green region = cols 0..35; a long green box with its centroid inside it pokes 20 cells out
    # on the right; a green box at cols 38..49 is misplaced but nearer the region than that edge
    obs = observation([(0, 10, 21, 14, 55), (0, 50, 61, 38, 49)])
    for policy in (DistanceHeuristic(envs[0]), AccessibilityHeuristic(envs[0])):
        _, row, col = cell(policy.predict(obs)[0])
        assert 50 <= row <= 61 and 38 <= col <= 49, type(policy).__name__


def test_a_thin_object_is_graspable_next_to_a_wide_one_of_its_class(envs):
    # regression: the cup-radius erosion fell back to the whole blob per class, not per object, so
    # a thin blue object (narrower than the cup) beside a wide blue one could never be chosen
    obs = observation([(2, 40, 51, 90, 101), (2, 60, 63, 20, 40)])  # the wide one is sorted
    for policy in (DistanceHeuristic(envs[0]), AccessibilityHeuristic(envs[0])):
        _, row, col = cell(policy.predict(obs)[0])
        assert 60 <= row <= 63 and 20 <= col <= 40, type(policy).__name__


def test_pick_only_layout_and_batches(envs):
    obs = observation([(1, 30, 41, 100, 111)])
    for env in envs:
        action, state = DistanceHeuristic(env).predict(obs, deterministic=True)
        assert state is None and cell(action)[0] == 0 and action < env.action_space.n
    batch, _ = AccessibilityHeuristic(envs[1]).predict(np.stack([obs, obs]))
    assert batch.shape == (2,)
    with pytest.raises(ValueError, match="observation shape"):
        DistanceHeuristic(envs[0]).predict(obs[:, :10])


def test_random_policy_covers_the_layout(envs):
    policy = RandomPolicy(envs[0], seed=0)
    actions = [int(policy.predict(observation([]))[0]) for _ in range(300)]
    assert max(actions) < envs[0].action_space.n and len({a // (H * W) for a in actions}) == 3


def test_heuristics_need_a_shelf_env():
    with pytest.raises(ValueError, match="ShelfSort-v0"):
        DistanceHeuristic(FindTheSquareEnv())
