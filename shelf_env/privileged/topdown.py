"""An unoccluded top-down heightmap read from the simulator: what a camera in the cabinet's roof would see.

The env's observation comes from a camera at the front opening, so the cells behind an object are
grey (occluded) and an object's back and depth are unknown. `topdown_observation` casts one vertical
ray per heightmap cell (PyBullet's ``rayTestBatch``, from just under the roof down to below the
floor) and recolours the top surface it hits exactly as the camera's map is recoloured
(`shelf_env.camera.heightmap.recolour`: class colours, white free space, tinted target regions, the
height channel), in the same layout and with no occluded cell. It reads the simulator, so it is
privileged: a diagnostic of how much the front view hides (docs/experiments/fall-visibility.md),
never a policy's input.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.actions import cell_centres
from shelf_env.camera.heightmap import FREE, recolour

#: How far under the roof the rays start (metres): inside the cabinet, above every object.
RAY_TOP_MARGIN = 0.002


def topdown_semantic(env: gym.Env) -> tuple[np.ndarray, np.ndarray]:
    """(cell uid (H, W) int, top surface height (H, W) metres) of ``env``'s current scene, seen from
    straight above every cell: an object's uid where a ray hits an object first, `FREE` (height 0)
    where it reaches the floor or hits anything that is not an object."""
    base: Any = env.unwrapped
    x, y = cell_centres(base.rows, base.cols, base.camera.pixel_size)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    top = params.CABINET_HEIGHT - RAY_TOP_MARGIN
    starts = np.c_[xx.ravel(), yy.ravel(), np.full(xx.size, top)]
    ends = np.c_[xx.ravel(), yy.ravel(), np.full(xx.size, -0.01)]
    hits = pb.rayTestBatch(starts.tolist(), ends.tolist(), physicsClientId=base.world.client)
    objects = {o.uid for o in base.world.objects}
    cell_uid = np.full(xx.size, FREE, dtype=np.int64)
    height = np.zeros(xx.size)
    for k, hit in enumerate(hits):
        if hit[0] in objects:
            cell_uid[k] = hit[0]
            height[k] = max(float(hit[3][2]), 0.0)
    return cell_uid.reshape(xx.shape), height.reshape(xx.shape)


def topdown_observation(env: gym.Env) -> np.ndarray:
    """The unoccluded top-down observation (C, H, W) uint8 of ``env``'s current scene, in the layout of
    its own observation (see the module docstring)."""
    base: Any = env.unwrapped
    cell_uid, height = topdown_semantic(env)
    return recolour(cell_uid, height, base._class_of_uid(), base._regions_mask)
