"""Fuzzing ShelfSort-v0: 20,000 actions over N = 1..14 and both object sets (slow; ``-m slow``).

    python -m pytest -q -m slow tests/test_fuzz.py          # 20,000 actions on 2 worker processes (~56 min)
    SHELF_FUZZ_ACTIONS=500 python -m pytest -q -m slow tests/test_fuzz.py   # a quick look

Every (object set, N) cell plays its share of actions, drawn from three streams in turn: uniform
over the whole action space, uniform over the env's action mask, and boundary indices (first and
last index, each map's corners and edges). Between them it throws bad actions at the env, which
must answer with the documented `ValueError` and leave the episode untouched. It checks every
step: observation shape and dtype, reward in {-10, -1, 0}, finite object poses, bool flags,
consistent info counters; and that the body count is the same after every reset (1,000 resets
and more over the run).

Run time (2026-11-23, the fast physics, 2 workers on an idle 2-core machine): 3347 s for 19,992
actions (714 per cell; now 715), 2150 resets, 812 bad actions refused, 746 falls, 157 sorted episodes.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

N_ACTIONS = int(os.environ.get("SHELF_FUZZ_ACTIONS", "20000"))
WORKERS = int(os.environ.get("SHELF_FUZZ_WORKERS", "2"))
REWARDS = {-10.0, -1.0, 0.0}
CELLS = [(object_set, n) for n in range(1, 15) for object_set in ("train", "ycb")]


def _boundary_actions(codec) -> list[int]:
    h, w = codec.rows, codec.cols
    out = [0, codec.n - 1]
    for name in codec.map_names:
        for row, col in ((0, 0), (0, w - 1), (h - 1, 0), (h - 1, w - 1), (0, w // 2), (h - 1, w // 2),
                         (h // 2, 0), (h // 2, w - 1)):
            out.append(codec.encode(name, row, col))
    return out


BAD_ACTIONS = [-1, 10**9, 2.5, True, "3", None, np.array([1, 2])]


def fuzz_cell(object_set: str, n: int, n_actions: int, seed: int) -> dict:
    """Play ``n_actions`` fuzzed actions in one (object set, N) cell; returns counts (asserts inside)."""
    import gymnasium as gym
    import pybullet as pb
    import torch

    import shelf_env  # noqa: F401
    from shelf_env.actions import ActionCodec

    torch.set_num_threads(1)
    rng = np.random.default_rng(seed)
    env = gym.make("ShelfSort-v0", num_objects=n, object_set=object_set).unwrapped
    codec = ActionCodec.of(env)
    boundary = _boundary_actions(codec)
    counts = {"actions": 0, "resets": 0, "bad": 0, "episodes_sorted": 0, "falls": 0}
    bodies = None
    obs, info = env.reset(seed=int(rng.integers(2**31)))
    try:
        while counts["actions"] < n_actions:
            if bodies is None:
                bodies = pb.getNumBodies(physicsClientId=env.client)
            assert pb.getNumBodies(physicsClientId=env.client) == bodies
            stream = counts["actions"] % 3
            if stream == 0:
                action = int(rng.integers(codec.n))
            elif stream == 1:
                action = int(rng.choice(np.flatnonzero(env.action_masks())))
            else:
                action = boundary[int(rng.integers(len(boundary)))]
            if counts["actions"] % 25 == 0:  # bad input: a clear error, nothing changed
                bad = BAD_ACTIONS[counts["bad"] % len(BAD_ACTIONS)]
                before = (env.action_count, env._obs.copy())
                with pytest.raises(ValueError, match="action"):
                    env.step(bad)
                assert env.action_count == before[0] and np.array_equal(env._obs, before[1])
                counts["bad"] += 1
            obs, reward, terminated, truncated, info = env.step(action)
            counts["actions"] += 1
            assert obs.shape == env.observation_space.shape and obs.dtype == np.uint8
            assert reward in REWARDS, reward
            assert isinstance(terminated, bool) and isinstance(truncated, bool)
            assert np.isfinite(env.world.positions()).all()
            assert 0 <= info["num_sorted"] <= info["num_objects"] == n
            assert info["action_count"] <= env.max_actions
            assert (reward == -10.0) == (terminated and not info["is_success"])  # invalid
            assert (reward == 0.0) == info["is_success"]
            if terminated or truncated:
                counts["episodes_sorted"] += bool(info["is_success"])
                counts["falls"] += bool(info["fell"])
                obs, info = env.reset(seed=int(rng.integers(2**31)))
                counts["resets"] += 1
                assert pb.getNumBodies(physicsClientId=env.client) == bodies
        # resets on their own, to reach 1,000 over the whole run
        for _ in range(-(-1000 // len(CELLS))):
            env.reset(seed=int(rng.integers(2**31)))
            counts["resets"] += 1
            assert pb.getNumBodies(physicsClientId=env.client) == bodies
    finally:
        env.close()
    return counts


@pytest.mark.slow
def test_fuzzed_actions_over_every_n_and_object_set():
    per_cell = max(1, -(-N_ACTIONS // len(CELLS)))  # at least N_ACTIONS in all (715 x 28 = 20,020)
    start = time.perf_counter()
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(max_workers=WORKERS, mp_context=ctx) as pool:
        futures = [pool.submit(fuzz_cell, o, n, per_cell, 1000 + i) for i, (o, n) in enumerate(CELLS)]
        results = [f.result() for f in futures]
    total = {k: sum(r[k] for r in results) for k in results[0]}
    print(f"\nfuzz: {total} in {time.perf_counter() - start:.0f} s on {WORKERS} workers")
    assert total["actions"] == per_cell * len(CELLS) >= N_ACTIONS
    assert total["bad"] >= total["actions"] // 25
    assert total["resets"] >= 1000
