"""The heuristic baselines H-d and H-a of §V-a, and a random-policy floor.

All of them act only through pick-and-place, choose only the pick pixel (the env's place
heuristic chooses where the object goes, exactly as for the learned policies) and see only the
observation — the recoloured heightmap — so they face the same partial observability as the
learned policy. They expose SB3's ``predict(obs, state, episode_start, deterministic)`` so that
one evaluation loop runs every policy.

They also take sb3-contrib's ``action_masks`` (``acts_masked`` is False: an evaluation does not pass
them the env's masks, and they keep choosing among their own candidates). Masks come from a
`sb3_pixeldqn.loop_breaker.LoopBreaker` (``"h-d+loop-breaker"`` in `shelf_env.evaluation.protocol`). H-d and
H-a then choose among the allowed cells of their candidates. Where no allowed cell is left, they
choose as they would unmasked (when every visible object is sorted, that means the allowed
graspable cells). The random policy draws among the allowed actions.

What they read from the observation (`ObservationView`): the class of each visible object cell
(its colour), the visible objects (connected blobs of one class colour), each class's target
region (the bounding box of its visible tint — regions are rectangles, and objects standing in a
region hide part of its tint) and the cells a suction cup can grip (cells at least a cup radius
inside their blob, or the whole blob when it is thinner than the cup). An object counts as
*sorted* when its blob's centroid lies in its class's region: the observable counterpart of the
env's rule (base position in the region). Without it a pixel rule keeps re-picking sorted objects
whose edge pokes out of their region.

- **H-d**: among graspable cells of unsorted objects, the one farthest from its class's region
  (§V-a: "evaluates each pixel's distance from the target region and selects the pixel with the
  largest distance").
- **H-a**: among graspable cells of unsorted objects, the one with the largest
  distance-from-region plus distance-from-the-back: objects in front are more accessible and
  hide others.

With the env's ``safe_picks=True`` both choose only among picks whose carry out of the opening
clears the other visible objects (`ObservationView.restrict_to_clear_carries`), as the env's mask
does for the learned policies.

When every visible object is sorted but the episode goes on, something is hidden: both pick the
front-most object, to reveal what it hides.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from shelf_env.camera.heightmap import CLASS_RGB, REGION_RGB, observed_height
from shelf_env.conditions.safe_picks import carry_clear
from shelf_env.env import ShelfSortEnv
from shelf_env.robot.placement import _window_sum

#: Cup radius in cells at the default 5 mm (13 mm cup): graspable cells are this far inside a blob.
CUP_MARGIN_M = 0.013


def object_classes(obs: np.ndarray) -> np.ndarray:
    """(H, W) int: the class of each visible object cell of ``obs`` (its class colour), -1 elsewhere."""
    rgb = np.moveaxis(obs[:3], 0, -1)
    object_class = np.full(obs.shape[1:], -1, dtype=np.int64)
    for k, colour in enumerate(CLASS_RGB):
        object_class[(rgb == colour).all(axis=-1)] = k
    return object_class


def object_blobs(obs: np.ndarray) -> np.ndarray:
    """(H, W) int: `ObservationView`'s ``blob`` alone (the visible objects as connected blobs of one class
    colour, numbered from 0; -1 elsewhere), without the view's regions and graspable cells."""
    return label_blobs(object_classes(obs))


@dataclass
class ObservationView:
    """What a heuristic reads from one observation ``(4, H, W)``."""

    object_class: np.ndarray  # (H, W) int: class of the visible object cell, -1 elsewhere
    blob: np.ndarray  # (H, W) int: index of the visible object (connected blob), -1 elsewhere
    regions: list[tuple[int, int, int, int] | None]  # per class (row0, row1, col0, col1), inclusive
    graspable: np.ndarray  # (H, W) bool: object cells a cup radius inside their blob
    sorted_cells: np.ndarray  # (H, W) bool: cells of objects whose blob centroid is in their region

    @classmethod
    def from_observation(cls, obs: np.ndarray, margin_cells: int) -> ObservationView:
        rgb = np.moveaxis(obs[:3], 0, -1)
        object_class = object_classes(obs)
        regions: list[tuple[int, int, int, int] | None] = []
        for colour in REGION_RGB:
            rows, cols = np.nonzero((rgb == colour).all(axis=-1))
            regions.append((rows.min(), rows.max(), cols.min(), cols.max()) if rows.size else None)
        blob = label_blobs(object_class)
        graspable = np.zeros_like(object_class, dtype=bool)
        sorted_cells = np.zeros_like(graspable)
        for b in range(blob.max() + 1):
            cells = blob == b
            inner = _erode(cells, margin_cells)
            graspable |= inner if inner.any() else cells
            rect = regions[object_class[cells][0]]
            rows, cols = np.nonzero(cells)
            r, c = rows.mean(), cols.mean()
            if rect is not None and rect[0] <= r <= rect[1] and rect[2] <= c <= rect[3]:
                sorted_cells |= cells
        return cls(object_class, blob, regions, graspable, sorted_cells)

    def restrict_to_clear_carries(self, obs: np.ndarray, pixel_size: float, max_shift: float = 0.0) -> None:
        """Keep only the graspable cells whose carry out of the opening clears the other visible
        objects (`shelf_env.conditions.safe_picks.carry_clear` on the blobs and the height channel), unless no
        unsorted object has one. Blobs are objects as the colours show them: touching objects of
        one class are one blob, so one of them is not an obstacle to the other. ``max_shift``: the
        sideways detour the closed loop's lane check may take (`ShelfSortEnv.detour_reach`)."""
        clear = self.graspable & carry_clear(self.blob, observed_height(obs), pixel_size, max_shift=max_shift)
        if (clear & ~self.sorted_cells).any():
            self.graspable = clear

    def restrict_to_allowed(self, picks: np.ndarray) -> None:
        """Keep only the graspable cells whose pick ``picks`` ((H, W) bool) allows: where an unsorted
        object keeps one, or where no object is unsorted and some cell is kept. Otherwise
        unchanged (see the module docstring)."""
        kept = self.graspable & picks
        if (kept & ~self.sorted_cells).any() or (kept.any() and not (self.graspable & ~self.sorted_cells).any()):
            self.graspable = kept

    def distance_to_region(self) -> np.ndarray:
        """(H, W) distance in cells from each object cell to its class's region rectangle (0 inside).

        A class whose region is not visible at all gets the largest distance of the map, so its
        objects are not mistaken for sorted ones.
        """
        h, w = self.object_class.shape
        rows, cols = np.mgrid[0:h, 0:w]
        dist = np.zeros((h, w))
        for k, rect in enumerate(self.regions):
            cells = self.object_class == k
            if rect is None:
                dist[cells] = float(np.hypot(h, w))
                continue
            r0, r1, c0, c1 = rect
            dr = np.maximum(np.maximum(r0 - rows, rows - r1), 0)
            dc = np.maximum(np.maximum(c0 - cols, cols - c1), 0)
            dist[cells] = np.hypot(dr, dc)[cells]
        return dist


def label_blobs(labels: np.ndarray) -> np.ndarray:
    """Connected components (4-neighbourhood) of the cells sharing a label >= 0: (H, W) int with
    blobs numbered 0..n-1 in raster order of their first cell, -1 where ``labels`` < 0.

    Min-index propagation: every cell repeatedly takes the smallest index among itself and its
    same-label neighbours, until nothing changes (at most a blob's longest path, in numpy steps).
    """
    h, w = labels.shape
    big = h * w
    idx = np.where(labels >= 0, np.arange(big).reshape(h, w), big)
    same_down = (labels[1:] == labels[:-1]) & (labels[1:] >= 0)
    same_right = (labels[:, 1:] == labels[:, :-1]) & (labels[:, 1:] >= 0)
    while True:
        new = idx.copy()
        new[1:] = np.where(same_down, np.minimum(new[1:], idx[:-1]), new[1:])
        new[:-1] = np.where(same_down, np.minimum(new[:-1], idx[1:]), new[:-1])
        new[:, 1:] = np.where(same_right, np.minimum(new[:, 1:], new[:, :-1]), new[:, 1:])
        new[:, :-1] = np.where(same_right, np.minimum(new[:, :-1], new[:, 1:]), new[:, :-1])
        if np.array_equal(new, idx):
            break
        idx = new
    out = np.full((h, w), -1, dtype=np.int64)
    roots = np.unique(idx[idx < big])
    out[idx < big] = np.searchsorted(roots, idx[idx < big])
    return out


def _erode(mask: np.ndarray, radius: int) -> np.ndarray:
    """Cells of ``mask`` whose whole (2r+1) x (2r+1) neighbourhood is in ``mask``."""
    side = 2 * radius + 1
    return _window_sum(mask, side, side) == side * side


class ObservationPolicy:
    """SB3's ``predict`` over one observation or a batch, for policies that act on one at a time."""

    observation_space: gym.spaces.Box
    action_space: gym.spaces.Discrete
    #: An evaluation passes no env masks (`shelf_env.evaluation.protocol.takes_action_masks`); masks given
    #: explicitly (a LoopBreaker's) restrict the choice (see the module docstring).
    acts_masked = False

    def predict(
        self,
        observation: np.ndarray,
        state: tuple | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, None]:
        obs = np.asarray(observation)
        shape = self.observation_space.shape
        n_actions = int(self.action_space.n)
        if obs.shape == shape:
            batch = obs[None]
        elif obs.ndim == 4 and obs.shape[1:] == shape:
            batch = obs
        else:
            raise ValueError(f"{type(self).__name__}: observation shape {obs.shape} is not {shape} or (n, *{shape})")
        masks: list[np.ndarray | None] = [None] * len(batch)
        if action_masks is not None:
            allowed = np.asarray(action_masks, dtype=bool)
            if allowed.size != len(batch) * n_actions:
                raise ValueError(f"{type(self).__name__}: action_masks has {allowed.size} entries; expected "
                                 f"{len(batch)} x {n_actions}")
            masks = list(allowed.reshape(len(batch), n_actions))
        actions = [self._act(o, m) for o, m in zip(batch, masks)]
        return (np.array(actions[0]) if obs.shape == shape else np.array(actions)), None

    def _act(self, obs: np.ndarray, allowed: np.ndarray | None = None) -> int:
        raise NotImplementedError


class PickHeuristic(ObservationPolicy):
    """Shared plumbing of H-d and H-a: the env's layout and the pick action of a chosen cell."""

    def __init__(self, env: gym.Env) -> None:
        base = env.unwrapped
        if not isinstance(base, ShelfSortEnv):
            raise ValueError(f"{type(self).__name__} needs a ShelfSort-v0 env, got {type(base).__name__}")
        if "pick" not in base.map_names:
            raise ValueError(f"{type(self).__name__} needs the pick primitive; the env has {base.map_names}")
        self.observation_space = base.observation_space
        self.action_space = base.action_space
        self.codec = base.codec
        self.rows, self.cols = base.rows, base.cols
        self.pixel_size = base.camera.pixel_size
        self.margin_cells = int(round(CUP_MARGIN_M / self.pixel_size))
        #: The env's ``safe_picks``: choose only among picks whose carry clears the neighbours
        #: (straight out, or by a sideways detour up to ``detour_reach`` m with the lane check).
        self.safe_picks = bool(getattr(base, "safe_picks", False))
        self.detour_reach = float(base.detour_reach)

    def _pick(self, row: int, col: int) -> int:
        return self.codec.encode("pick", int(row), int(col))

    def _act(self, obs: np.ndarray, allowed: np.ndarray | None = None) -> int:
        view = ObservationView.from_observation(obs, self.margin_cells)
        if self.safe_picks:
            view.restrict_to_clear_carries(obs, self.pixel_size, self.detour_reach)
        if allowed is not None:
            view.restrict_to_allowed(allowed.reshape(-1, self.rows, self.cols)[self.codec.map_index("pick")])
        if not view.graspable.any():  # nothing visible: pick the middle of the floor (a no-op probe)
            return self._pick(self.rows // 2, self.cols // 2)
        return self.act_on(view, obs)

    def act_on(self, view: ObservationView, obs: np.ndarray) -> int:
        """The action for an observation with something graspable: the pick of `choose`'s cell."""
        return self._pick(*self.choose(view))

    def score(self, view: ObservationView) -> np.ndarray:
        """(H, W) preference of each candidate cell (graspable, of an unsorted object); -inf elsewhere."""
        raise NotImplementedError

    def choose(self, view: ObservationView) -> tuple[int, int]:
        """The best-scoring candidate cell; the front-most object when every visible one is sorted."""
        score = self.score(view)
        if not np.isfinite(score).any():
            return front_most(view.graspable)
        row, col = np.unravel_index(int(np.argmax(score)), score.shape)
        return int(row), int(col)


class DistanceHeuristic(PickHeuristic):
    """H-d: pick the graspable cell of an unsorted object farthest from its class's target region
    (front-most on ties); if every visible object is sorted, the front-most object."""

    def score(self, view: ObservationView) -> np.ndarray:
        # ties: the front-most cell. Distinct distances (square roots of integers below 2 * 120^2)
        # differ by more than 1e-3, so the 1e-6-per-row bonus only breaks ties.
        rows = np.arange(self.rows)[:, None] * np.ones((1, self.cols))
        candidates = view.graspable & ~view.sorted_cells
        return np.where(candidates, view.distance_to_region() + 1e-6 * rows, -np.inf)


class AccessibilityHeuristic(PickHeuristic):
    """H-a: among graspable cells of unsorted objects, maximise distance-from-region +
    ``front_weight`` x distance-from-the-back (both in cells); if every visible object is sorted,
    the front-most object."""

    def __init__(self, env: gym.Env, front_weight: float = 1.0) -> None:
        super().__init__(env)
        self.front_weight = front_weight

    def score(self, view: ObservationView) -> np.ndarray:
        candidates = view.graspable & ~view.sorted_cells
        rows = np.arange(self.rows)[:, None] * np.ones((1, self.cols))  # row index = distance from the back
        return np.where(candidates, view.distance_to_region() + self.front_weight * rows, -np.inf)


def front_most(cells: np.ndarray) -> tuple[int, int]:
    """The front-most (largest row) of ``cells``, the middle one of that row's cells."""
    rows, cols = np.nonzero(cells)
    front = cols[rows == rows.max()]
    return int(rows.max()), int(front[len(front) // 2])


class RandomPolicy(ObservationPolicy):
    """Uniform over all actions of the env's layout: the floor every policy must beat."""

    def __init__(self, env: gym.Env, seed: int | None = None) -> None:
        if not isinstance(env.action_space, gym.spaces.Discrete) or not isinstance(env.observation_space,
                                                                                    gym.spaces.Box):
            raise ValueError(f"RandomPolicy needs a Box observation and a Discrete action space, got "
                             f"{env.observation_space} and {env.action_space}")
        self.action_space = env.action_space
        self.observation_space = env.observation_space
        self.rng = np.random.default_rng(seed)

    def _act(self, obs: np.ndarray, allowed: np.ndarray | None = None) -> int:
        if allowed is not None and allowed.any():
            return int(self.rng.choice(np.flatnonzero(allowed)))
        return int(self.rng.integers(int(self.action_space.n)))
