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
- ``h-a-1cm-push`` (`AccessibilityPushFallback`): H-a at 1 cm cells that pushes where it is masked out of every
  candidate pick of every unsorted object (under the filter: where every one is risky), with the privileged
  lookahead's push candidates (`LookaheadHeuristic.push_candidates`, which read only the observation) but nothing
  probed. A test of the reading that the Q-maps' share is what they do when every pick looks risky.
- ``+push-fallback`` (`PushFallback`): the same rule around a checkpoint, innermost (under the filter and the guard).
- ``+risk-trace`` (`RiskTrace`, outermost): changes nothing; counts in the episode's ``policy_stats`` how often the
  chosen pick is one the shipped risk calls risky, and how often no unsorted object had a cell it calls safe.

Importing the module registers them (`shelf_env.policies`): ``h-d-1cm+shipped-filter+pick-guard+loop-breaker`` is
H-d under the shipped policy's wrappers, in the shipped order.
"""

from __future__ import annotations

import pathlib
from typing import Any

import gymnasium as gym
import numpy as np

from shelf_env.baselines.heuristics import (
    CUP_MARGIN_M,
    AccessibilityHeuristic,
    DistanceHeuristic,
    ObservationView,
    PickHeuristic,
)
from shelf_env.fall_filter import GEOMETRY_FILTER, FallFilter, GeometryRisk, geometry_risk_path
from shelf_env.policies import POLICIES, WRAPPERS, PolicyFactory, register_policy, register_wrapper
from shelf_env.privileged.lookahead import LookaheadHeuristic

#: The shipped P+S's checkpoint and the geometry risk model beside it (relative to the repository root, where
#: evaluations run): ``+shipped-filter`` is the product's ``+geometry-filter`` of that checkpoint.
SHIPPED_CHECKPOINT = "examples/pretrained/p_s.zip"
SHIPPED_RISK = geometry_risk_path(SHIPPED_CHECKPOINT)
#: The wrapper's suffix.
SHIPPED_FILTER = "+shipped-filter"
#: The cell size (m) the shipped risk model reads: its observations are 40 x 60.
CELL_1CM = 0.01
#: The diagnostic wrapper's suffix.
RISK_TRACE = "+risk-trace"


def _check(base: str) -> None:
    if not SHIPPED_RISK.is_file():
        raise ValueError(f"{SHIPPED_FILTER} reads the shipped geometry risk model at {SHIPPED_RISK}, which is missing "
                         "(run from the repository root)")


def _wrap(agent: Any, env: gym.Env, base: str) -> FallFilter:
    return WRAPPERS[GEOMETRY_FILTER].wrap(agent, env, SHIPPED_CHECKPOINT)


class AccessibilityPushFallback(AccessibilityHeuristic):
    """H-a, except where masks (a filter's) leave no inner cell of any object that looks unsorted: then the first
    allowed push of `LookaheadHeuristic.push_candidates` (beside each object at its middle row, towards its region
    first; unsorted objects first, front first), unprobed. Without masks, or with no allowed push, it is H-a."""

    push_candidates = LookaheadHeuristic.push_candidates  # camera-only: it reads the view, the codec and the layout

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.stats = {"push_fallbacks": 0}

    def fallback(self, obs: np.ndarray, allowed: np.ndarray) -> int | None:
        """The push for ``obs`` where ``allowed`` (flat) leaves no inner cell of any object that looks unsorted: the
        first allowed one of `push_candidates`; None where a candidate pick is left, or no candidate push is allowed."""
        view = ObservationView.from_observation(obs, self.margin_cells)
        picks = allowed.reshape(-1, self.rows, self.cols)[self.codec.map_index("pick")]
        unsorted = view.graspable & ~view.sorted_cells
        if unsorted.any() and not (unsorted & picks).any():
            for action in self.push_candidates(view):  # type: ignore[misc]
                if allowed[action]:
                    return int(action)
        return None

    def _act(self, obs: np.ndarray, allowed: np.ndarray | None = None) -> int:
        push = None if allowed is None else self.fallback(obs, allowed)
        if push is not None:
            self.stats["push_fallbacks"] += 1
            return push
        return super()._act(obs, allowed)


class PushFallback:
    """``+push-fallback``, innermost around a checkpoint: where the masks it is given (the filter's and the guard's,
    which wrap it) leave no inner cell of any object that looks unsorted, the push `AccessibilityPushFallback` would
    take, instead of the policy's choice; the policy's choice elsewhere. Counts ``push_fallbacks``."""

    def __init__(self, policy: Any, env: gym.Env) -> None:
        self.policy, self.rule = policy, AccessibilityPushFallback(env)
        self.observation_space, self.action_space = policy.observation_space, policy.action_space
        self.acts_masked = bool(getattr(policy, "acts_masked", True))
        self.stats = {"push_fallbacks": 0}

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        if action_masks is not None:
            push = self.rule.fallback(np.asarray(observation), np.asarray(action_masks, bool).reshape(-1))
            if push is not None:
                self.stats["push_fallbacks"] += 1
                return np.array(push), state
        return self.policy.predict(observation, state=state, episode_start=episode_start,
                                   deterministic=deterministic, action_masks=action_masks)


def _factory(heuristic: type[PickHeuristic]) -> PolicyFactory:
    def make(env: gym.Env, seed: int) -> PickHeuristic:
        return heuristic(env)
    return make


for _name, _heuristic in (("h-d-1cm", DistanceHeuristic), ("h-a-1cm", AccessibilityHeuristic),
                          ("h-a-1cm-push", AccessibilityPushFallback)):
    if _name not in POLICIES:  # the module may be imported twice (a worker, a test)
        register_policy(_name, _factory(_heuristic), pixel_size=CELL_1CM)
register_wrapper(SHIPPED_FILTER, _wrap, check=_check, files=lambda base: [SHIPPED_RISK])
#: The push fallback for a checkpoint's suffix (innermost: it acts on the masks the filter and the guard pass down).
PUSH_FALLBACK = "+push-fallback"
register_wrapper(PUSH_FALLBACK, lambda agent, env, base: PushFallback(agent, env))


class RiskTrace:
    """An outermost wrapper that changes nothing: the policy's action, passed through, with counters (``stats``) of
    what the shipped risk ``risk`` says of it. ``decisions``: calls; ``picks``: the chosen action is a pick;
    ``risky_picks``: a pick at a cell the risk calls risky (at or over its threshold); ``no_safe``: calls in which no
    object that looks unsorted has an inner cell (a heuristic's candidate, `ObservationView.graspable`) that the risk
    calls safe, where a heuristic under the filter keeps its own, risky, candidates."""

    STATS = ("decisions", "picks", "risky_picks", "no_safe")

    def __init__(self, policy: Any, risk: GeometryRisk, map_names: tuple[str, ...], rows: int, cols: int,
                 margin_cells: int) -> None:
        self.policy, self.risk = policy, risk
        self.observation_space, self.action_space = policy.observation_space, policy.action_space
        self.acts_masked = bool(getattr(policy, "acts_masked", True))
        self.pick, self.cells, self.cols, self.margin_cells = map_names.index("pick"), rows * cols, cols, margin_cells
        self.stats = dict.fromkeys(self.STATS, 0)

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        action, state = self.policy.predict(observation, state=state, episode_start=episode_start,
                                            deterministic=deterministic, action_masks=action_masks)
        obs = np.asarray(observation)
        risky = self.risk.risk(obs) >= self.risk.threshold
        view = ObservationView.from_observation(obs, self.margin_cells)
        m, cell = divmod(int(np.asarray(action).reshape(-1)[0]), self.cells)
        self.stats["decisions"] += 1
        self.stats["no_safe"] += int(not (view.graspable & ~view.sorted_cells & ~risky).any())
        if m == self.pick:
            self.stats["picks"] += 1
            self.stats["risky_picks"] += int(risky.reshape(-1)[cell])
        return action, state


def _trace(agent: Any, env: gym.Env, base: str) -> RiskTrace:
    unwrapped: Any = env.unwrapped
    return RiskTrace(agent, GeometryRisk.load(SHIPPED_RISK), tuple(unwrapped.map_names), unwrapped.rows,
                     unwrapped.cols, int(round(CUP_MARGIN_M / unwrapped.camera.pixel_size)))


register_wrapper(RISK_TRACE, _trace, check=_check, files=lambda base: [SHIPPED_RISK])


def trace_table(trace: pathlib.Path, played: pathlib.Path) -> str:
    """Markdown: per ``+risk-trace`` policy in the evaluation folder ``trace``, its episodes and the trace's counters,
    after checking that every traced episode ended exactly as the same policy's episode in ``played`` where both were
    played on one machine (the wrapper changes no action; PyBullet's floating point differs between CPUs, so episodes
    from two machines are counted, not compared). `ValueError` naming the first episode that differs or is missing."""
    from shelf_env.evaluation.protocol import load_cells

    def key(r: Any) -> tuple:
        return r.num_objects, r.seed, r.run

    before = {(r.policy, *key(r)): r for r in load_cells(played)}
    rows = ["| policy | episodes | sorted | fell | decisions | picks | risky picks (of picks) | no safe candidate "
            "(of decisions) | fell episodes with a risky pick | checked against the untraced (other machine) |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    by_policy: dict[str, list[Any]] = {}
    for r in load_cells(trace):
        if r.policy.endswith(RISK_TRACE):
            by_policy.setdefault(r.policy, []).append(r)
    if not by_policy:
        raise ValueError(f"{trace} has no cells of a {RISK_TRACE} policy")
    for policy, records in sorted(by_policy.items()):
        plain = policy[:-len(RISK_TRACE)]
        elsewhere = 0
        for r in records:
            old = before.get((plain, *key(r)))
            where = f"{policy} N={r.num_objects} seed {r.seed} run {r.run}"
            if old is None:
                raise ValueError(f"{where}: no such episode of {plain} in {played}")
            if old.machine != r.machine:
                elsewhere += 1
                continue
            if (old.success, old.actions, old.failure) != (r.success, r.actions, r.failure):
                raise ValueError(f"{where} ended {r.success, r.actions, r.failure}, {plain} in {played} "
                                 f"{old.success, old.actions, old.failure}")
        total = {k: sum(r.policy_stats.get(k, 0) for r in records) for k in RiskTrace.STATS}
        fell = [r for r in records if r.fell]
        rows.append(f"| {plain} | {len(records)} | {sum(r.success for r in records)} | {len(fell)} | "
                    f"{total['decisions']} | {total['picks']} | {total['risky_picks']} "
                    f"({100 * total['risky_picks'] / max(total['picks'], 1):.1f} %) | {total['no_safe']} "
                    f"({100 * total['no_safe'] / max(total['decisions'], 1):.1f} %) | "
                    f"{sum(r.policy_stats.get('risky_picks', 0) > 0 for r in fell)} of {len(fell)} | "
                    f"{len(records) - elsewhere} ({elsewhere}) |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m research.wrapped_heuristics TRACE PLAYED --out FILE``: `trace_table`, written atomically (stdout
    is not the place: PyBullet prints its build time there)."""
    import argparse
    import sys

    from shelf_env.files import write_text_atomically

    parser = argparse.ArgumentParser(description=trace_table.__doc__)
    parser.add_argument("trace", type=pathlib.Path, help="an evaluation folder with +risk-trace policies' cells")
    parser.add_argument("played", type=pathlib.Path, help="the folder with the same policies' cells, untraced")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="the Markdown table's file")
    args = parser.parse_args(argv)
    try:
        table = trace_table(args.trace, args.played)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    write_text_atomically(args.out, table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
