"""A tiered geometry filter: safe picks first, the risky-but-allowed ones only when no safe pick is left.

The shipped filter (`shelf_env.fall_filter.FallFilter`) masks picks at risk >= 0.1. Its greedy falls on validation
scenes mostly come from picks just under that (0.05-0.1; docs/experiments/stricter-filter.md), but masking those
always (threshold 0.05) turned as many scenes into time-outs as it saved from falls: with every pick of the
remaining objects masked, the policy can only push. This filter masks picks at risk >= `PREFER` (0.05) only while
some allowed pick on a visible object stays below it, and otherwise the filter's own threshold (the file's, 0.1):
the policy does the safe picks first, and an object whose picks are all risky is picked, as before, once nothing
safer is left (its blockers may have moved away by then, and its risk with them).

``<checkpoint>+tiered-filter`` plays the checkpoint under it with the geometry risk saved beside it (as
``+geometry-filter``); registered by importing this module (`research.evaluate` does).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from shelf_env.baselines.heuristics import object_blobs
from shelf_env.fall_filter import FallFilter, GeometryRisk, PickRisk, geometry_risk_path
from shelf_env.policies import WRAPPERS, register_wrapper

#: Picks at or over this risk are masked while an allowed pick on an object stays below it (fixed, not searched).
PREFER = 0.05
#: The wrapper's suffix.
TIERED_FILTER = "+tiered-filter"


class TieredFilter(FallFilter):
    """`FallFilter` whose threshold is `PREFER` while an allowed pick on a visible object is below it, and the risk
    model's own threshold otherwise. Counts ``tightened`` decisions (those played at `PREFER`) besides the filter's."""

    STATS = ("masked", "unfiltered")

    def __init__(self, policy: Any, risk: PickRisk, map_names: tuple[str, ...], rows: int, cols: int,
                 prefer: float = PREFER) -> None:
        super().__init__(policy, risk, map_names, rows, cols)
        if not 0 < prefer <= risk.threshold:
            raise ValueError(f"prefer must be in (0, {risk.threshold}] (the risk's threshold), got {prefer}")
        self.prefer = float(prefer)
        self.tightened = 0

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        if action_masks is None:
            raise ValueError("TieredFilter needs the env's action masks")
        obs, allowed = self.observation(observation), self.allowed(action_masks)
        risk = self.risk.risk(obs)
        picks = allowed.reshape(self.n_maps, self.rows, self.cols)[self.pick] & (object_blobs(obs) >= 0)
        threshold = self.risk.threshold
        if (picks & (risk < self.prefer)).any():
            threshold = self.prefer
            self.tightened += 1
        return self.choose(obs, allowed, risk >= threshold, state, deterministic)


def _tiered(agent: Any, env: gym.Env, base: str) -> TieredFilter:
    unwrapped: Any = env.unwrapped
    return TieredFilter(agent, GeometryRisk.load(geometry_risk_path(base)), tuple(unwrapped.map_names),
                        unwrapped.rows, unwrapped.cols)


register_wrapper(TIERED_FILTER, _tiered, check=WRAPPERS["+geometry-filter"].check,
                 files=lambda base: [geometry_risk_path(base)])
