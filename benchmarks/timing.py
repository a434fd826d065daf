"""Timing helpers the benchmark scripts share."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from shelf_env.evaluation.protocol import scene_seed

#: ``(observation, action mask)`` of a scene's first state.
State = tuple[np.ndarray, np.ndarray]


def seconds_per_call(call: Callable[[Any], Any], items: Sequence[Any]) -> float:
    """Mean wall seconds of ``call(item)`` over ``items``, after one warm-up call (imports, caches, allocations)."""
    call(items[0])
    start = time.perf_counter()
    for item in items:
        call(item)
    return (time.perf_counter() - start) / len(items)


def first_states(env: gym.Env, num_objects: int, scenes: int) -> list[State]:
    """The first state of runs 0 .. ``scenes`` - 1 of evaluation seed 0 at ``num_objects`` (the env's N)."""
    states = []
    for run in range(scenes):
        obs, _ = env.reset(seed=scene_seed(0, num_objects, run))
        states.append((obs, env.unwrapped.action_masks()))
    return states


def seconds_per_action(env: gym.Env, num_objects: int, states: Sequence[State],
                       act: Callable[[np.ndarray, np.ndarray], int], count: int = 5) -> float:
    """Mean wall seconds of one env step from the first ``count`` of ``states`` (`first_states`), each scene reset
    again and stepped with ``act(obs, masks)``; the decision itself is not timed."""
    total = 0.0
    for run, (obs, masks) in enumerate(states[:count]):
        env.reset(seed=scene_seed(0, num_objects, run))
        action = int(act(obs, masks))
        start = time.perf_counter()
        env.step(action)
        total += time.perf_counter() - start
    return total / len(states[:count])
