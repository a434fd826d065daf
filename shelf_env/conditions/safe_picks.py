"""Which picks can be carried out of the cabinet without sweeping a neighbour out with them.

The pick primitive (`shelf_env.robot.primitives.Primitives.pick`) lifts the gripped object as high as the
ceiling allows and carries it straight out of the opening. The object hangs under the cup: gripped
on its top at height ``h`` (the observed surface height of the pick cell) it spans
``[z_carry - h, z_carry]`` during the carry, where ``z_carry`` is the highest TCP height under the
ceiling (18.5 cm in the 27 cm cabinet). Any object between it and the opening whose top is higher
than ``z_carry - h`` is in its way and is shoved, or dragged, out of the cabinet: the paper's main
failure (§V-d), and in our evaluations the cause of most falls of every policy (results/models).

`carry_clear` reads that from a heightmap: a pick cell is *clear* when every other visible object
in the corridor swept by its object — the object's columns widened by ``side_cells``, from its
back-most visible row to the front of the cabinet — is lower than ``z_carry - h - tolerance``. It
uses only what the camera sees (object cells and their heights), so a policy can compute it too;
what it cannot know is what is hidden (an object occluded behind another is not in the corridor of
anything in front of it, so this rarely matters) and how objects swing in the cup.
"""

from __future__ import annotations

import numpy as np

from shelf_env import params
from shelf_env.robot.arm import MotionConfig, carry_height

#: TCP height of the carry with the default motion: the tool's top 5 mm under the ceiling.
Z_CARRY = carry_height(MotionConfig())
#: Lateral margin of the swept corridor, and vertical margin over a neighbour's top.
SIDE_M = 0.005
TOLERANCE_M = 0.005


def _maps(labels: np.ndarray, height: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    labels, height = np.asarray(labels), np.asarray(height, dtype=float)
    if labels.shape != height.shape or labels.ndim != 2:
        raise ValueError(f"labels and height must be (H, W) maps of one shape, got {labels.shape} and {height.shape}")
    return labels, height


def _tallest_on_path(obstacle: np.ndarray, box: tuple[int, int, int, int], shift: int, side_cells: int) -> float | None:
    """The tallest obstacle swept by an object spanning rows ``r0..r1`` and columns ``c0..c1``
    (``box``) when it is carried ``shift`` columns sideways along its own rows, then straight out
    to the front row, both corridors widened by ``side_cells``; None when the shift would bring it
    within ``side_cells`` + 1 of a side wall (the straight carry, shift 0, is judged anywhere)."""
    r0, r1, c0, c1 = box
    lo, hi = c0 + shift - side_cells, c1 + shift + side_cells
    if shift and (lo < 1 or hi > obstacle.shape[1] - 2):
        return None
    sideways = obstacle[r0:r1 + 1, max(min(c0, c0 + shift) - side_cells, 0):max(c1, c1 + shift) + side_cells + 1]
    way_out = obstacle[r0:, max(lo, 0):hi + 1]
    return max(float(sideways.max(initial=0.0)), float(way_out.max(initial=0.0)))


def _object(labels: np.ndarray, height: np.ndarray, uid: int
            ) -> tuple[np.ndarray, tuple[int, int, int, int], np.ndarray]:
    """The object's cells, their bounding box (r0, r1, c0, c1) and the others' heights (0 elsewhere)."""
    own = labels == uid
    rr, cc = np.nonzero(own)
    obstacle = np.where((labels >= 0) & ~own, height, 0.0)
    return own, (int(rr.min()), int(rr.max()), int(cc.min()), int(cc.max())), obstacle


def carry_clear(labels: np.ndarray, height: np.ndarray, pixel_size: float = params.PIXEL_SIZE,
                z_carry: float = Z_CARRY, side: float = SIDE_M, tolerance: float = TOLERANCE_M,
                max_shift: float = 0.0) -> np.ndarray:
    """(H, W) bool: the object cells whose pick can be carried out of the opening clear of the others.

    ``labels`` (H, W) int: one id per visible object (an object uid, or a blob index), < 0 where no
    object is seen; ``height`` (H, W): the observed surface height in metres. Rows run from the
    back (row 0) to the front, as in the env's observation. With ``max_shift`` > 0, a carry that
    first moves the object sideways by up to that many metres (as the closed loop's lane check
    does, `carry_path`) counts too.
    """
    labels, height = _maps(labels, height)
    side_cells, reach = int(round(side / pixel_size)), int(round(max_shift / pixel_size))
    clear = np.zeros(labels.shape, dtype=bool)
    for uid in np.unique(labels[labels >= 0]):
        own, box, obstacle = _object(labels, height, uid)
        tops = (_tallest_on_path(obstacle, box, shift, side_cells) for shift in range(-reach, reach + 1))
        lowest = min(top for top in tops if top is not None)  # the straight carry is always judged
        # gripped at a cell of height h, the object's bottom is z_carry - h during the carry
        clear |= own & (height + lowest < z_carry - tolerance)
    return clear


def carry_path(labels: np.ndarray, height: np.ndarray, row: int, col: int,
               pixel_size: float = params.PIXEL_SIZE, z_carry: float = Z_CARRY, side: float = SIDE_M,
               tolerance: float = TOLERANCE_M, max_shift: float = 0.2) -> int | None:
    """The nearest clear way out for the object picked at cell (``row``, ``col``): the lateral shift
    in cells (0: straight out, as `carry_clear`; > 0 towards larger columns) of a carry that first
    moves the object sideways at carry height and then straight out of the opening, with every
    other visible object in both swept corridors lower than the object's bottom; None when no
    shift up to ``max_shift`` m is clear. An empty cell (``labels`` < 0) gives 0: nothing is known
    about what the cup will hold, so the carry goes straight as without the check.

    The sideways corridor is the object's own rows, over the columns between its place and the
    shifted one, widened by ``side``; the way out is as in `carry_clear`, at the shifted columns.
    A shifted object keeps ``side`` + one cell from the side walls (the map's edges); the straight
    carry is judged wherever the object is.
    """
    labels, height = _maps(labels, height)
    rows, cols = labels.shape
    if not (0 <= row < rows and 0 <= col < cols):
        raise ValueError(f"cell ({row}, {col}) is outside the {rows}x{cols} map")
    uid = labels[row, col]
    if uid < 0:
        return 0
    _, box, obstacle = _object(labels, height, uid)
    bottom = z_carry - float(height[row, col]) - tolerance  # the object's bottom during the carry
    side_cells, reach = int(round(side / pixel_size)), int(round(max_shift / pixel_size))
    for shift in sorted(range(-reach, reach + 1), key=lambda s: (abs(s), s)):
        top = _tallest_on_path(obstacle, box, shift, side_cells)
        if top is not None and top < bottom:
            return shift
    return None
