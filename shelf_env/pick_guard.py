"""A camera-only guard against wasted picks: ``<policy>+pick-guard``.

Replayed on validation scenes at N = 10, the P+S shipped before this guard
(``p_s.zip+geometry-filter+loop-breaker``) ran out of actions like this: with one to three objects left, its Q-maps
ranked a pick of an object already in its class's region highest, the pick put it back about where it was, and the
episode spent its remaining actions there (35 of 40 actions on one sorted object in one scene; the loop breaker
only moved the picks to neighbouring cells of the same object). In another scene the object it re-picked straddled
two regions, so that it did not look sorted, and the same waste followed. The heuristics never pick an object that
looks sorted (`shelf_env.baselines.heuristics.ObservationView.sorted_cells`: a blob whose centroid lies in its
class's region as the region tints show it).

`PickGuard` wraps a policy whose ``predict`` takes sb3-contrib's ``action_masks`` and masks out the pick
cells of

- the objects that look sorted, by that same reading of the observation, and
- the objects (visible blobs) that already hold ``max_picks`` of the episode's earlier pick cells: an object
  picked that often and still there was put back where it was.

Pushes are left alone (a push of a sorted object can make room). Where that would leave no allowed action
the policy chooses as if unguarded. It reads nothing but the observation and the picks it returned, so a
robot can run it; it is not learned. Its memory is per episode, cleared where ``episode_start`` is True
(the evaluation passes it at every reset; `sb3_pixeldqn.LoopBreaker` passes it on) or by `reset`. Every pick it returns
counts as one: under the loop breaker, a first answer the breaker asks again about (its cell is banned, so
that object was picked there before) counts as well as the answer that is executed. Its counters:
``guarded`` (decisions where at least one allowed pick cell was masked out) and ``unguarded`` (decisions
where nothing allowed was left).

`shelf_env.policies` registers the suffix: the shipped P+S is ``p_s.zip+geometry-filter+pick-guard+loop-breaker``
(examples/pretrained/README.md). The experiment that chose it and its numbers: docs/experiments/pick-guard.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from shelf_env.baselines.heuristics import ObservationView
from shelf_env.fall_filter import PickMask

#: The suffix: ``<checkpoint>+geometry-filter+pick-guard+loop-breaker`` guards the filtered policy's picks.
PICK_GUARD = "+pick-guard"


class PickGuard(PickMask):
    """Wrap ``policy``: pick cells of objects that look sorted, or that hold ``max_picks`` of the episode's
    earlier picks, are masked out before it chooses (module docstring)."""

    STATS = ("guarded", "unguarded")

    def __init__(self, policy: Any, map_names: tuple[str, ...], rows: int, cols: int, max_picks: int = 3) -> None:
        super().__init__(policy, map_names, rows, cols)
        if isinstance(max_picks, bool) or not isinstance(max_picks, int) or max_picks < 1:
            raise ValueError(f"max_picks must be an integer >= 1, got {max_picks!r}")
        self.max_picks = max_picks
        self._picks: list[tuple[int, int]] = []

    def reset(self) -> None:
        """Forget the episode's picks (as ``episode_start`` True does)."""
        self._picks = []

    def guarded_cells(self, obs: np.ndarray) -> np.ndarray:
        """Bool ``(H, W)``: the cells of the objects that look sorted in ``obs`` or hold ``max_picks`` earlier picks."""
        view = ObservationView.from_observation(obs, margin_cells=0)
        cells = view.sorted_cells.copy()
        if self._picks:
            rows, cols = np.array(self._picks).T
            hit = view.blob[rows, cols]
            counts = np.bincount(hit[hit >= 0], minlength=int(view.blob.max()) + 1)
            for b in np.flatnonzero(counts >= self.max_picks):
                cells |= view.blob == b
        return cells

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        obs, allowed = self.observation(observation), self.allowed(action_masks)
        if episode_start is not None and bool(np.asarray(episode_start).reshape(-1)[0]):
            self._picks = []
        action, state = self.choose(obs, allowed, self.guarded_cells(obs), state, deterministic)
        m, rest = divmod(int(np.asarray(action).reshape(-1)[0]), self.rows * self.cols)
        if m == self.pick:
            self._picks.append(divmod(rest, self.cols))
        return action, state
