"""`shelf_env.actions.ActionCodec`: the one mapping between action indices, cells and cabinet points."""

import gymnasium as gym
import numpy as np
import pytest

from shelf_env import params
from shelf_env.actions import ACTION_X_MAX, ACTION_Y_MAX, ActionCodec, map_names


@pytest.fixture(scope="module")
def codec():
    return ActionCodec.for_primitives(("pick", "push"), 0.005)


def test_layout_and_index_round_trip(codec):
    assert codec.map_names == ("pick", "push_left", "push_right")
    assert (codec.rows, codec.cols, codec.n) == (80, 120, 3 * 80 * 120)
    assert codec.encode("pick", 0, 0) == 0 and codec.encode("push_right", 79, 119) == codec.n - 1
    assert codec.encode("push_left", 2, 3) == 80 * 120 + 2 * 120 + 3
    rng = np.random.default_rng(0)
    for a in [0, codec.n - 1, *rng.integers(codec.n, size=200).tolist()]:
        assert codec.encode(*codec.decode(a)) == a
    assert codec.decode(np.array([7])) == ("pick", 0, 7)
    s = ActionCodec.for_primitives(("pick",), 0.01)
    assert s.map_names == ("pick",) and s.n == 40 * 60 and map_names(("pick",)) == ["pick"]


def test_cells_and_cabinet_points(codec):
    # row 0 is the back of the cabinet, col 0 the camera's left (+y)
    x, y = codec.cell_centre(0, 0)
    assert x == pytest.approx(params.CABINET_DEPTH - 0.0025) and y == pytest.approx(params.CABINET_WIDTH / 2 - 0.0025)
    assert codec.cell_of(x, y) == (0, 0)
    for row, col in [(5, 7), (79, 119), (40, 60)]:
        assert codec.cell_of(*codec.cell_centre(row, col)) == (row, col)
    assert codec.cell_of(-1.0, -1.0) == (79, 119) and codec.cell_of(9.0, 9.0) == (0, 0)  # clipped
    assert codec.action_at("push_left", *codec.cell_centre(3, 4)) == codec.encode("push_left", 3, 4)
    # the tool target keeps clear of the back and side walls
    name, tx, ty = codec.target(codec.encode("pick", 0, 0))
    assert name == "pick" and tx == ACTION_X_MAX and ty == ACTION_Y_MAX


def test_mirror_swaps_pushes_and_reverses_columns(codec):
    assert codec.mirror(codec.encode("push_left", 3, 0)) == codec.encode("push_right", 3, 119)
    assert codec.mirror(codec.encode("pick", 10, 20)) == codec.encode("pick", 10, 99)
    _, x, y = codec.target(codec.encode("pick", 10, 20))
    _, mx, my = codec.target(codec.mirror(codec.encode("pick", 10, 20)))
    assert (mx, my) == pytest.approx((x, -y))


@pytest.mark.parametrize("bad, match", [(-1, "out of range"), (3 * 80 * 120, "out of range"), (1.5, "integer"),
                                        (True, "integer"), (np.array([1, 2]), "single integer")])
def test_bad_indices(codec, bad, match):
    with pytest.raises(ValueError, match=match):
        codec.decode(bad)


def test_bad_cells_maps_and_layouts(codec):
    with pytest.raises(ValueError, match="outside the 80 x 120"):
        codec.encode("pick", 80, 0)
    with pytest.raises(ValueError, match="unknown map 'rotate'"):
        codec.encode("rotate", 0, 0)
    with pytest.raises(ValueError, match="distinct"):
        ActionCodec(("pick", "pick"), 4, 6, 0.01)
    with pytest.raises(ValueError, match="not a ShelfSort-v0 env"):
        ActionCodec.of(gym.make("CartPole-v1"))


def test_the_env_decodes_and_targets_with_its_codec():
    env = gym.make("ShelfSort-v0", num_objects=1, primitives=("pick",), pixel_size=0.01)
    try:
        codec = ActionCodec.of(env)  # through the wrappers
        assert codec == ActionCodec.for_primitives(("pick",), 0.01)
        assert env.action_space.n == codec.n and env.observation_space.shape[1:] == (codec.rows, codec.cols)
        assert env.unwrapped.decode_action(1234) == codec.decode(1234)
    finally:
        env.close()
