"""Where a filtered policy's greedy falls come from: pushes or picks, and for picks the filter's own risk there.

`shelf_env.evaluation.falls` counts how often a policy's greedy action would drop an object; this asks which of its
actions do. The policy plays greedily, each decision is tried first in a forked copy of the simulator (as there:
`probe_outcome`; an action that would end the episode invalid is replaced by the privileged lookahead's, so every
state the policy reaches is measured), and each decision is recorded with its primitive and, where the checkpoint has
a geometry risk beside it (``<stem>.geometry_risk.pt``), that risk at the chosen cell (for picks).

    python -m research.fall_sources \\
        results/fall_geometry/filter/p_s_geo10.zip+geometry-filter+pick-guard+loop-breaker \\
        --ns 8 --runs 30 --seed 2000 --out results/stricter_filter/sources_val.json

Use validation seeds (2000, ...): the numbers describe a policy; a next step is aimed with them.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Any

import numpy as np

from sb3_pixeldqn.loop_breaker import predict_takes
from shelf_env.evaluation.falls import RESCUE
from shelf_env.evaluation.protocol import (
    check_ns,
    greedy_action,
    make_env,
    make_policy,
    scene_seed,
    takes_action_masks,
)
from shelf_env.fall_filter import GeometryRisk, geometry_risk_path
from shelf_env.files import write_json_atomically
from shelf_env.policies import POLICIES, policy_wrappers
from shelf_env.privileged.lookahead import probe_outcome

#: Upper edges of the risk bins the pick decisions are counted in (the last bin is everything above).
RISK_BINS = (0.02, 0.05, 0.1)


def episode_decisions(env: Any, policy: Any, rescue: Any, risk: GeometryRisk | None, reset_seed: int) -> list[dict]:
    """Every greedy decision of one episode: its map, cell, the risk there (picks, with a risk model), and whether
    it would have ended the episode invalid / with a fall."""
    unwrapped: Any = env.unwrapped
    maps, rows, cols = tuple(unwrapped.map_names), int(unwrapped.rows), int(unwrapped.cols)
    masked, starts = takes_action_masks(policy), predict_takes(policy, "episode_start")
    obs, _ = env.reset(seed=reset_seed)
    decisions: list[dict] = []
    while True:
        action = greedy_action(env, policy, obs, not decisions, masked, starts)
        primitive, cell = divmod(action, rows * cols)
        row, col = divmod(cell, cols)
        outcome = probe_outcome(env, action)
        record = {"map": maps[primitive], "row": row, "col": col, "invalid": not outcome.valid,
                  "fell": bool(outcome.fell), "risk": None}
        if risk is not None and maps[primitive] == "pick":
            record["risk"] = float(risk.risk(np.asarray(obs))[row, col])
        decisions.append(record)
        if not outcome.valid:
            action = int(np.asarray(rescue.predict(obs, deterministic=True)[0]).reshape(-1)[0])
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            return decisions


def summary(decisions: list[dict]) -> dict[str, Any]:
    """Decisions and falls per map, and the picks' by risk bin (edges `RISK_BINS`)."""
    out: dict[str, Any] = {"decisions": len(decisions), "fell": sum(d["fell"] for d in decisions)}
    for name in sorted({d["map"] for d in decisions}):
        mine = [d for d in decisions if d["map"] == name]
        out[name] = {"decisions": len(mine), "fell": sum(d["fell"] for d in mine),
                     "invalid": sum(d["invalid"] for d in mine)}
    risked = [d for d in decisions if d["risk"] is not None]
    if risked:
        edges = (0.0, *RISK_BINS, float("inf"))
        out["pick_risk_bins"] = [
            {"from": lo, "to": hi if np.isfinite(hi) else None,
             "decisions": sum(lo <= d["risk"] < hi for d in risked),
             "fell": sum(lo <= d["risk"] < hi and d["fell"] for d in risked)}
            for lo, hi in zip(edges[:-1], edges[1:])]
    return out


def measure(policy: str, ns: list[int], seed: int, runs: int, out: pathlib.Path) -> dict[str, Any]:
    """Every episode of ``policy`` at each N; written to ``out`` after each N."""
    check_ns(ns)
    name, _ = policy_wrappers(policy)
    risk = GeometryRisk.load(geometry_risk_path(name)) if name not in POLICIES and \
        geometry_risk_path(name).is_file() else None
    results: dict[str, Any] = {"policy": policy, "seed": seed, "runs": runs, "cells": {}}
    for n in ns:
        env = make_env(policy, n, "ycb")
        try:
            agent = make_policy(policy, env, seed=scene_seed(seed, n, 10**6))
            rescue = POLICIES[RESCUE](env, 0)
            episodes = [episode_decisions(env, agent, rescue, risk, scene_seed(seed, n, run)) for run in range(runs)]
        finally:
            env.close()
        flat = [d for e in episodes for d in e]
        results["cells"][str(n)] = {**summary(flat), "episodes": episodes}
        print(n, summary(flat), flush=True)
        write_json_atomically(out, results)
    return results


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m research.fall_sources", description=__doc__.split("\n")[0])
    p.add_argument("policy", help="a policy name or PixelDoubleDQN zip with wrappers (as shelf-evaluate takes it)")
    p.add_argument("--ns", type=int, nargs="+", default=[8])
    p.add_argument("--runs", type=int, default=30)
    p.add_argument("--seed", type=int, default=2000, help="evaluation seed of the scenes (a validation seed)")
    p.add_argument("--out", type=pathlib.Path, required=True)
    args = p.parse_args(argv)
    try:
        measure(args.policy, args.ns, args.seed, args.runs, args.out)
    except ValueError as err:
        print(f"fall_sources: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
