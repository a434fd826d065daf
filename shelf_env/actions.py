"""The one action codec of ShelfSort-v0: (map, row, col) <-> flat action index <-> cabinet (x, y).

The action space is ``Discrete(n_maps * H * W)`` with ``a = m * H * W + row * W + col``; rows run
from the back of the cabinet (row 0) to the front, columns from the camera's left (col 0, +y) to
its right. Every part of the project that turns an index into a pixel or a place in the cabinet,
or back, goes through an `ActionCodec`: the env (decoding and the tool's target), the heuristics,
the symmetry transforms, evaluation, the demo, the benchmarks and the tests.
(`sb3_pixeldqn` keeps its own env-agnostic split of an index into a map and a pixel.)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from numbers import Integral
from typing import Any

import numpy as np

from shelf_env import params

PRIMITIVES = ("pick", "push")
#: Tool targets stay 2 cm short of the back wall and 8 mm from the side walls, where the blade's
#: tip and thickness would hit them.
ACTION_X_MAX = params.CABINET_DEPTH - 0.02
ACTION_Y_MAX = params.CABINET_WIDTH / 2 - 0.008
#: The map that mirrors each map across the cabinet's width.
MIRROR_MAP = {"pick": "pick", "push_left": "push_right", "push_right": "push_left"}


def map_names(primitives: Sequence[str]) -> list[str]:
    """Q-map layout for a primitive set: "push" contributes push_left then push_right."""
    names: list[str] = []
    for p in primitives:
        names += ["push_left", "push_right"] if p == "push" else [p]
    return names


def cell_centres(rows: int, cols: int, pixel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """Cabinet x of every heightmap row (back -> front) and y of every column (left -> right)."""
    x = params.CABINET_DEPTH - (np.arange(rows) + 0.5) * pixel_size
    y = params.CABINET_WIDTH / 2 - (np.arange(cols) + 0.5) * pixel_size
    return x, y


def clip_target(x: float, y: float) -> tuple[float, float]:
    """Keep a tool target where the blade's tip and thickness clear the walls."""
    return float(np.clip(x, 0.0, ACTION_X_MAX)), float(np.clip(y, -ACTION_Y_MAX, ACTION_Y_MAX))


@dataclass(frozen=True)
class ActionCodec:
    """Flat action indices of one map layout on one heightmap grid.

    :param map_names: Q-map names in action order (`map_names`).
    :param rows: heightmap rows H (cabinet depth / pixel size).
    :param cols: heightmap columns W (cabinet width / pixel size).
    :param pixel_size: cell size in metres.
    """

    map_names: tuple[str, ...]
    rows: int
    cols: int
    pixel_size: float
    _x: np.ndarray = field(init=False, repr=False, compare=False)
    _y: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "map_names", tuple(self.map_names))
        if not self.map_names or len(set(self.map_names)) != len(self.map_names):
            raise ValueError(f"map_names must be distinct names, got {self.map_names!r}")
        if self.rows < 1 or self.cols < 1 or self.pixel_size <= 0:
            raise ValueError(f"need rows, cols >= 1 and pixel_size > 0, got {self.rows}, {self.cols}, "
                             f"{self.pixel_size}")
        x, y = cell_centres(self.rows, self.cols, self.pixel_size)
        object.__setattr__(self, "_x", x)
        object.__setattr__(self, "_y", y)

    @classmethod
    def for_primitives(cls, primitives: Sequence[str], pixel_size: float) -> ActionCodec:
        """The codec of an env with these primitives and cell size."""
        rows = int(round(params.CABINET_DEPTH / pixel_size))
        cols = int(round(params.CABINET_WIDTH / pixel_size))
        return cls(tuple(map_names(primitives)), rows, cols, float(pixel_size))

    @classmethod
    def of(cls, env: Any) -> ActionCodec:
        """The codec of a ShelfSort-v0 env, through any wrappers."""
        codec = getattr(getattr(env, "unwrapped", env), "codec", None)
        if not isinstance(codec, ActionCodec):
            raise ValueError(f"{type(env).__name__} is not a ShelfSort-v0 env (it has no action codec)")
        return codec

    @property
    def n(self) -> int:
        """Number of actions (the size of the Discrete action space)."""
        return len(self.map_names) * self.rows * self.cols

    @property
    def cells(self) -> int:
        return self.rows * self.cols

    # ---- index <-> (map, row, col) ----------------------------------------------------
    def map_index(self, map_name: str) -> int:
        if map_name not in self.map_names:
            raise ValueError(f"unknown map {map_name!r}; this layout has {list(self.map_names)}")
        return self.map_names.index(map_name)

    def encode(self, map_name: str, row: int, col: int) -> int:
        """Flat index of ``(map_name, row, col)``."""
        m = self.map_index(map_name)
        if not (0 <= row < self.rows and 0 <= col < self.cols):
            raise ValueError(f"cell ({row}, {col}) outside the {self.rows} x {self.cols} heightmap")
        return (m * self.rows + int(row)) * self.cols + int(col)

    def decode(self, action: Any) -> tuple[str, int, int]:
        """``(map name, row, col)`` of a flat index; `ValueError` if ``action`` is not one."""
        if isinstance(action, np.ndarray):
            if action.size != 1:
                raise ValueError(f"action must be a single integer, got an array of shape {action.shape}")
            action = action.reshape(()).item()
        if isinstance(action, bool) or not isinstance(action, Integral):
            raise ValueError(f"action must be an integer, got {action!r}")
        index = int(action)
        if not 0 <= index < self.n:
            raise ValueError(f"action {index} out of range [0, {self.n})")
        m, rest = divmod(index, self.cells)
        row, col = divmod(rest, self.cols)
        return self.map_names[m], row, col

    # ---- (row, col) <-> cabinet (x, y) ----------------------------------------------
    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """``(row, col)`` of the heightmap cell containing cabinet point (x, y) (clipped to the grid)."""
        row = int(np.clip((params.CABINET_DEPTH - x) // self.pixel_size, 0, self.rows - 1))
        col = int(np.clip((params.CABINET_WIDTH / 2 - y) // self.pixel_size, 0, self.cols - 1))
        return row, col

    def cell_centre(self, row: int, col: int) -> tuple[float, float]:
        """Cabinet (x, y) of a cell's centre."""
        return float(self._x[row]), float(self._y[col])

    def action_at(self, map_name: str, x: float, y: float) -> int:
        """Flat index of the cell containing cabinet point (x, y) on the named map."""
        return self.encode(map_name, *self.cell_of(x, y))

    def target(self, action: Any) -> tuple[str, float, float]:
        """``(map name, x, y)``: the tool target of an action (its cell centre, clear of the walls)."""
        name, row, col = self.decode(action)
        return (name, *clip_target(*self.cell_centre(row, col)))

    # ---- symmetry -------------------------------------------------------------------
    def mirror(self, action: Any) -> int:
        """The action mirrored across the cabinet's width: column W-1-col, push-left <-> push-right."""
        name, row, col = self.decode(action)
        if name not in MIRROR_MAP:
            raise ValueError(f"no mirror image for map {name!r}")
        return self.encode(MIRROR_MAP[name], row, self.cols - 1 - col)


def occupancy_masks(occupied: np.ndarray, pixel_size: float, names: Sequence[str],
                    pick: np.ndarray | None = None) -> np.ndarray:
    """The allowed actions of ShelfSort-v0 (`ShelfSortEnv.action_masks`) given the visible object cells
    ``occupied`` ((H, W) bool), flat in the order of the maps ``names``: a pick on an object cell (or
    where ``pick`` allows one), a push whose blade (one row either side of its start cell) meets an
    object cell within the push length in its direction. Nothing visible: every action is allowed."""
    rows, cols_n = occupied.shape
    band = occupied.copy()  # the blade is ~1 cm (2 cells) deep: count neighbouring rows
    band[1:] |= occupied[:-1]
    band[:-1] |= occupied[1:]
    reach = int(round(params.PUSH_LENGTH / pixel_size))
    counts = np.concatenate([np.zeros((rows, 1), dtype=np.int64), np.cumsum(band, axis=1)], axis=1)
    cols = np.arange(cols_n)
    masks = {
        "pick": occupied if pick is None else pick,
        # push-left moves towards col 0: objects in cols [c - reach, c]
        "push_left": (counts[:, cols + 1] - counts[:, np.maximum(cols - reach, 0)]) > 0,
        "push_right": (counts[:, np.minimum(cols + reach, cols_n - 1) + 1] - counts[:, cols]) > 0,
    }
    mask = np.concatenate([masks[name].reshape(-1) for name in names])
    if not mask.any():  # nothing visible (e.g. perception noise dropped every object): no guidance
        mask[:] = True
    return mask

