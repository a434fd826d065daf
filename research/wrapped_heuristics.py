"""The heuristics under the shipped P+S's camera-only wrappers (docs/experiments/wrapped-heuristics.md).

The shipped P+S is its Q-maps played under three test-time wrappers that read only the camera's heightmap and the
policy's own actions: the geometry pick filter (`shelf_env.fall_filter`, its risk model
``examples/pretrained/p_s.geometry_risk.pt`` at its own threshold), the pick guard and the loop breaker. Its margin
over H-d and H-a is measured against the bare heuristics. This module lets the heuristics play under the same
wrappers, so that the margin can be split into what the wrappers give any policy and what the Q-maps add:

- ``h-d-1cm`` and ``h-a-1cm``: H-d and H-a acting at 1 cm cells (40 x 60), the cell size the risk model reads
  (the bare heuristics act at the env default, 0.5 cm). Played bare they are the control for the cell size.
- ``+shipped-filter``: `FallFilter` with the shipped risk model, for any policy at 1 cm cells (``+geometry-filter``
  reads the model saved beside a checkpoint, which a heuristic has not). Evaluations fingerprint the model file.

Importing the module registers them (`shelf_env.policies`): ``h-d-1cm+shipped-filter+pick-guard+loop-breaker`` is
H-d under the shipped policy's wrappers, in the shipped order.
"""

from __future__ import annotations

import pathlib
from typing import Any

import gymnasium as gym

from shelf_env.baselines.heuristics import AccessibilityHeuristic, DistanceHeuristic
from shelf_env.fall_filter import FallFilter, GeometryRisk
from shelf_env.policies import POLICIES, register_policy, register_wrapper

#: The shipped P+S's geometry risk model (relative to the repository root, where evaluations run).
SHIPPED_RISK = pathlib.Path("examples/pretrained/p_s.geometry_risk.pt")
#: The wrapper's suffix.
SHIPPED_FILTER = "+shipped-filter"
#: The cell size (m) the shipped risk model reads: its observations are 40 x 60.
CELL_1CM = 0.01


def _check(base: str) -> None:
    if not SHIPPED_RISK.is_file():
        raise ValueError(f"{SHIPPED_FILTER} reads the shipped geometry risk model at {SHIPPED_RISK}, which is missing "
                         "(run from the repository root)")


def _wrap(agent: Any, env: gym.Env, base: str) -> FallFilter:
    unwrapped: Any = env.unwrapped
    return FallFilter(agent, GeometryRisk.load(SHIPPED_RISK), unwrapped.map_names, unwrapped.rows, unwrapped.cols)


def _distance(env: gym.Env, seed: int) -> DistanceHeuristic:
    return DistanceHeuristic(env)


def _accessibility(env: gym.Env, seed: int) -> AccessibilityHeuristic:
    return AccessibilityHeuristic(env)


for _name, _factory in (("h-d-1cm", _distance), ("h-a-1cm", _accessibility)):
    if _name not in POLICIES:  # the module may be imported twice (a worker, a test)
        register_policy(_name, _factory, pixel_size=CELL_1CM)
register_wrapper(SHIPPED_FILTER, _wrap, check=_check, files=lambda base: [SHIPPED_RISK])
