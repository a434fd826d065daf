"""The greedy action's fall rate per action, measured in forked copies of the env on held-out scenes.

A policy's SR says how often an episode ends well; a learner needs finer numbers: how often its
greedy action drops an object, per action. Measured here on the policy's own states: it plays
greedily (masked argmax, as `shelf-evaluate` acts), and before each of its actions that action is
tried in a forked copy of the simulator (`shelf_env.privileged.lookahead.probe_outcome`). An action that
would end the episode invalid (an object falls out, or the scene does not come to rest) is counted
and replaced by the privileged one-step lookahead's choice (``h-d-lookahead``, the *rescue*), so the
episode goes on and every state the policy reaches is measured, not only those before its first fall.

Up to its first rescue an episode is exactly the greedy policy's own (the env is history-free and
the probe leaves it untouched), so the same run gives the greedy SR of `shelf_env.evaluation.protocol`:
the episodes sorted in fewer than ``max_actions`` actions with no rescue.

    python -m shelf_env.evaluation.falls examples/pretrained/p_s.zip h-d --ns 5 8 11 --runs 12 \\
        --seed 2000 --out results/distill_scaling/falls.json

Scenes: `protocol.scene_seed(seed, N, run)`, YCB objects; use a seed that no training or choice read
for a claim (`VALIDATION_SEED` is the one distilled models are compared on). The JSON file holds one
entry per (policy, N) cell, written atomically as each cell finishes; running the command again skips
the cells already there (a cell of a zip is keyed by the file's digest, so a retrained file is measured
again).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from sb3_pixeldqn.loop_breaker import predict_takes
from shelf_env import params
from shelf_env.evaluation.protocol import (
    check_ns,
    greedy_action,
    make_env,
    make_policy,
    policy_digest,
    scene_seed,
    takes_action_masks,
)
from shelf_env.files import write_json_atomically
from shelf_env.policies import POLICIES
from shelf_env.privileged.lookahead import probe_outcome

#: Evaluation seed of the scenes distilled models are compared on (the scaling curve, the choice of a
#: model to ship): a validation set. Final claims use the §V seeds 0..S-1, which no choice reads.
VALIDATION_SEED = 2000
#: The privileged policy whose action replaces a greedy action that would end the episode invalid.
RESCUE = "h-d-lookahead"


@dataclass(frozen=True)
class FallEpisode:
    """One measured episode: the policy's decisions, how many of them would have ended it invalid
    (``fell``: an object out of the cabinet; the rest left the scene unstable), and how it ended."""

    run: int
    decisions: int
    invalid: int
    fell: int
    greedy_success: bool  # sorted in < max_actions actions without a rescue: the greedy policy's own episode
    first_invalid: int  # the decision (0-based) of the first invalid action, -1 if none


def measure_episode(env: Any, policy: Any, rescue: Any, reset_seed: int, run: int,
                    max_actions: int = params.MAX_ACTIONS,
                    on_decision: Callable[[np.ndarray, int, Any], None] | None = None) -> FallEpisode:
    """Play ``policy`` greedily from the scene of ``reset_seed``, probing each of its actions first
    (module docstring). ``on_decision(obs, action, outcome)``, where given, sees each greedy decision and its probed
    outcome (`probe_outcome`) before the env steps (a research script's per-decision record)."""
    masked, starts = takes_action_masks(policy), predict_takes(policy, "episode_start")
    obs, _ = env.reset(seed=reset_seed)
    decisions = invalid = fell = 0
    first_invalid = -1
    while True:
        action = greedy_action(env, policy, obs, decisions == 0, masked, starts)
        outcome = probe_outcome(env, action)
        if on_decision is not None:
            on_decision(obs, action, outcome)
        if not outcome.valid:
            invalid += 1
            fell += int(outcome.fell)
            if first_invalid < 0:
                first_invalid = decisions
            action = int(np.asarray(rescue.predict(obs, deterministic=True)[0]).reshape(-1)[0])
        decisions += 1
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    success = bool(info["is_success"]) and int(info["action_count"]) < max_actions and first_invalid < 0
    return FallEpisode(run, decisions, invalid, fell, success, first_invalid)


def measure_cell(policy: str, num_objects: int, seed: int, runs: int, object_set: str = "ycb") -> list[FallEpisode]:
    """The ``runs`` episodes of one (policy, N, seed) cell."""
    env = make_env(policy, num_objects, object_set)
    try:
        agent = make_policy(policy, env, seed=scene_seed(seed, num_objects, 10**6))
        rescue = POLICIES[RESCUE](env, 0)
        return [measure_episode(env, agent, rescue, scene_seed(seed, num_objects, run), run) for run in range(runs)]
    finally:
        env.close()


def cell_summary(episodes: list[FallEpisode]) -> dict[str, Any]:
    """Decisions, invalid and fallen actions, the rates per action, the greedy SR (%), and two numbers
    that one stuck episode cannot dominate: the episodes with an invalid greedy action at all
    (``episodes_invalid``: those the greedy policy itself would have lost to it) and the median over
    episodes of each one's invalid rate. A policy that, rescued, keeps choosing the same falling
    action piles up to 40 invalid actions in one scene: the pooled rate then says more about that
    scene than about the policy."""
    decisions = sum(e.decisions for e in episodes)
    invalid = sum(e.invalid for e in episodes)
    fell = sum(e.fell for e in episodes)
    rates = [e.invalid / e.decisions for e in episodes if e.decisions]
    return {"episodes": len(episodes), "decisions": decisions, "invalid": invalid, "fell": fell,
            "invalid_rate": invalid / decisions if decisions else float("nan"),
            "fall_rate": fell / decisions if decisions else float("nan"),
            "episodes_invalid": sum(e.invalid > 0 for e in episodes),
            "median_episode_rate": float(np.median(rates)) if rates else float("nan"),
            "sr": 100.0 * sum(e.greedy_success for e in episodes) / len(episodes) if episodes else float("nan")}


def cell_key(policy: str, num_objects: int, seed: int, runs: int, object_set: str) -> str:
    """A cell's key in the results file; a checkpoint's names the first 12 hex digits of the SHA-256 of
    the files it reads (`protocol.policy_digest`, as the evaluation's cells record it)."""
    digest = policy_digest(policy)
    tag = f"{policy}@{digest[:12]}" if digest else policy
    return f"{tag}|{object_set}|N={num_objects}|seed={seed}|runs={runs}"


def measure(policies: list[str], ns: list[int], seed: int, runs: int, out: pathlib.Path | None = None,
            object_set: str = "ycb") -> dict[str, Any]:
    """Every (policy, N) cell, resuming from and saving to ``out`` (JSON) as each cell finishes."""
    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")
    check_ns(ns)
    ns = list(dict.fromkeys(int(n) for n in ns))  # in the order given
    results: dict[str, Any] = {}
    if out is not None and out.exists():
        results = json.loads(out.read_text())
    for n in ns:  # every policy at one N before the next N: a stopped run compares like with like
        for policy in policies:
            key = cell_key(policy, n, seed, runs, object_set)
            if key in results:
                continue
            episodes = measure_cell(policy, n, seed, runs, object_set)
            results[key] = {"policy": policy, "num_objects": n, "seed": seed, "object_set": object_set,
                            **cell_summary(episodes), "per_episode": [asdict(e) for e in episodes]}
            print(json.dumps({k: v for k, v in results[key].items() if k != "per_episode"}), flush=True)
            if out is not None:
                write_json_atomically(out, results)
    return results


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m shelf_env.evaluation.falls", description=__doc__.split("\n")[0])
    p.add_argument("policies", nargs="+", help="policy names or PixelDoubleDQN zips (as shelf-evaluate takes them)")
    p.add_argument("--ns", type=int, nargs="+", default=[8], help="numbers of objects")
    p.add_argument("--runs", type=int, default=12, help="episodes per (policy, N)")
    p.add_argument("--seed", type=int, default=VALIDATION_SEED, help="evaluation seed of the scenes")
    p.add_argument("--object-set", default="ycb", choices=("ycb", "train"))
    p.add_argument("--out", type=pathlib.Path, default=None, help="JSON results file (resumed if it exists)")
    args = p.parse_args(argv)
    try:
        measure(args.policies, args.ns, args.seed, args.runs, args.out, args.object_set)
    except ValueError as err:
        print(f"falls: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
