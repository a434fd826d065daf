"""The heightmap: positions, heights, occlusion and colours."""

import numpy as np

from shelf_env import params
from shelf_env.camera.heightmap import CLASS_RGB, FREE, OCCLUDED, OCCLUDED_RGB, REGION_RGB
from tests.conftest import REGIONS, box


def test_empty_cabinet_is_all_seen_free_and_tinted(env):
    env.set_scene([(box(0.04, 0.04, 0.05), 0, 0.02 + 0.02, 0.27, 0.0)], REGIONS)
    cell_uid, height = env._semantic
    assert (cell_uid == OCCLUDED).mean() < 0.02
    obs = env._obs
    rgb = obs[:3].transpose(1, 2, 0)
    # a free cell in the middle region is tinted with that region's colour
    r, c = env.codec.cell_of(0.2, 0.0)
    assert (rgb[r, c] == REGION_RGB[1]).all() and obs[3, r, c] == 0


def test_known_box_appears_at_the_right_pixels_and_height(env):
    sx, sy, h = 0.06, 0.10, 0.08
    x, y = 0.25, 0.10
    env.set_scene([(box(sx, sy, h), 2, x, y, 0.0)], REGIONS)
    cell_uid, height = env._semantic
    uid = env.world.objects[0].uid
    ps = env.camera.pixel_size
    rows = np.arange(env.rows)
    cols = np.arange(env.cols)
    cx = params.CABINET_DEPTH - (rows + 0.5) * ps
    cy = params.CABINET_WIDTH / 2 - (cols + 0.5) * ps
    inside = (np.abs(cx - x) < sx / 2)[:, None] & (np.abs(cy - y) < sy / 2)[None, :]
    grown = (np.abs(cx - x) < sx / 2 + ps)[:, None] & (np.abs(cy - y) < sy / 2 + ps)[None, :]
    labelled = cell_uid == uid
    assert labelled[inside].mean() > 0.97  # the top face is seen (camera above the box)
    assert not labelled[~grown].any()  # and nothing beyond one cell of its edges
    assert np.allclose(height[inside & labelled], h, atol=0.004)
    obs = env._obs
    assert (obs[:3].transpose(1, 2, 0)[inside & labelled] == CLASS_RGB[2]).all()
    assert abs(int(np.median(obs[3][inside])) - round(h / params.CABINET_HEIGHT * 255)) <= 2


def test_cells_behind_a_tall_object_are_grey(env):
    # tall, thin-in-depth box near the front in the middle; the camera sees over it only far back
    env.set_scene([(box(0.04, 0.12, 0.16), 1, 0.08, 0.0, 0.0)], REGIONS)
    cell_uid, _ = env._semantic
    rgb = env._obs[:3].transpose(1, 2, 0)
    behind = [env.codec.cell_of(x, 0.0) for x in (0.12, 0.15, 0.18)]
    for r, c in behind:
        assert cell_uid[r, c] == OCCLUDED and (rgb[r, c] == OCCLUDED_RGB).all()
    # beside it the floor is seen
    r, c = env.codec.cell_of(0.15, 0.2)
    assert cell_uid[r, c] == FREE
    # the occluded object top is not visible, so the box's footprint is only partly labelled
    assert (cell_uid == env.world.objects[0].uid).sum() > 0
