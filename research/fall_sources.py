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

from shelf_env.baselines.heuristics import object_blobs
from shelf_env.evaluation.falls import RESCUE, measure_episode
from shelf_env.evaluation.protocol import (
    check_ns,
    make_env,
    make_policy,
    scene_seed,
)
from shelf_env.fall_filter import GeometryRisk, geometry_risk_path
from shelf_env.files import write_json_atomically
from shelf_env.policies import POLICIES, policy_wrappers
from shelf_env.privileged.lookahead import probe_outcome

#: Upper edges of the risk bins the pick decisions are counted in (the last bin is everything above).
RISK_BINS = (0.02, 0.05, 0.1)


def episode_decisions(env: Any, policy: Any, rescue: Any, risk: GeometryRisk | None, reset_seed: int,
                      alternatives: bool = False) -> list[dict]:
    """Every greedy decision of one episode: its map, cell, the risk there (picks, with a risk model), and whether
    it would have ended the episode invalid / with a fall. With ``alternatives`` (and a risk model), a pick is also
    compared with the lowest-risk cell of the same object (as the heuristics' blobs see it): that cell's risk, and,
    where it is another cell, whether picking it instead would have ended the episode invalid / with a fall, and how
    many objects each would have left sorted."""
    unwrapped: Any = env.unwrapped
    maps, rows, cols = tuple(unwrapped.map_names), int(unwrapped.rows), int(unwrapped.cols)
    decisions: list[dict] = []

    def record(obs: np.ndarray, action: int, outcome: Any) -> None:
        primitive, cell = divmod(action, rows * cols)
        row, col = divmod(cell, cols)
        decision = {"map": maps[primitive], "row": row, "col": col, "invalid": not outcome.valid,
                    "fell": bool(outcome.fell), "sorted": outcome.num_sorted, "risk": None}
        if risk is not None and maps[primitive] == "pick":
            risk_map = risk.risk(np.asarray(obs))
            decision["risk"] = float(risk_map[row, col])
            if alternatives:
                decision.update(safest_cell(env, obs, risk_map, primitive * rows * cols, row, col))
        decisions.append(decision)

    measure_episode(env, policy, rescue, reset_seed, run=0, on_decision=record)
    return decisions


def safest_cell(env: Any, obs: np.ndarray, risk_map: np.ndarray, offset: int, row: int, col: int) -> dict[str, Any]:
    """The lowest-risk cell of the object under the pick at (``row``, ``col``) and, where it is another cell, the
    probed outcome of picking it instead (``offset``: the pick map's first action)."""
    blobs = object_blobs(np.asarray(obs))
    if blobs[row, col] < 0:
        return {"alt_risk": None}
    cells = np.flatnonzero(blobs.reshape(-1) == blobs[row, col])
    best = int(cells[np.argmin(risk_map.reshape(-1)[cells])])
    out: dict[str, Any] = {"alt_risk": float(risk_map.reshape(-1)[best]),
                           "alt_same": best == row * blobs.shape[1] + col}
    if not out["alt_same"]:
        alt = probe_outcome(env, offset + best)
        out.update(alt_invalid=not alt.valid, alt_fell=bool(alt.fell), alt_sorted=alt.num_sorted)
    return out


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
    compared = [d for d in risked if d.get("alt_risk") is not None]
    if compared:
        moved = [d for d in compared if not d["alt_same"]]
        out["safest_cell"] = {"picks": len(compared), "already_safest": len(compared) - len(moved),
                              "moved": len(moved), "fell": sum(d["fell"] for d in moved),
                              "alt_fell": sum(d["alt_fell"] for d in moved),
                              "fell_alt_kept": sum(d["fell"] and not d["alt_invalid"] for d in moved),
                              "valid_both": sum(not d["invalid"] and not d["alt_invalid"] for d in moved),
                              "valid_both_alt_sorted_fewer": sum(
                                  not d["invalid"] and not d["alt_invalid"]
                                  and (d["alt_sorted"] or 0) < (d["sorted"] or 0) for d in moved)}
    return out


def measure(policy: str, ns: list[int], seed: int, runs: int, out: pathlib.Path,
            alternatives: bool = False) -> dict[str, Any]:
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
            episodes = [episode_decisions(env, agent, rescue, risk, scene_seed(seed, n, run), alternatives)
                        for run in range(runs)]
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
    p.add_argument("--alternatives", action="store_true",
                   help="also probe each pick's object at its lowest-risk cell (where that is another cell)")
    args = p.parse_args(argv)
    try:
        measure(args.policy, args.ns, args.seed, args.runs, args.out, args.alternatives)
    except ValueError as err:
        print(f"fall_sources: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
