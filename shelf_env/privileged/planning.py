"""A planning teacher: short rollouts of the one-step lookahead from each of its safe candidates.

The one-step lookahead (`shelf_env.privileged.lookahead`) never drops an object it could avoid
dropping, but it takes the first safe candidate in its base heuristic's order, so it does not plan
the sort: at N = 13-14 most of its episodes run out of their 40 actions. `PlanningTeacher` looks
further. At each decision it probes every candidate (one pick per visible object in H-d's order,
or the uncovering picks, then pushes at objects), keeps the first ``max_candidates`` that leave the
scene valid (a push only where it changes the observation), and from each runs, in a forked copy
of the simulator, the one-step lookahead for ``horizon`` - 1 more steps. A rollout's score is its
discounted return under the env's reward (−1 a step, 0 sorted, the invalid reward on a fall) plus,
where it has not ended, an optimistic value of the rest: one action per object not yet in its
region, discounted (−(1 − γ^u) / (1 − γ) for u such objects). It takes the best-scoring candidate
(ties: the lookahead's order), a sorting step at once, and its score is the decision's ``value``,
a value estimate in the env's units that the teacher dataset records.

Privileged (it reads the simulator), for teaching and as a reference, never a baseline. Its cost per
decision is about candidates x horizon x (1 + the lookahead's probes per step) env actions;
``stats`` counts them (``actions``) and ``benchmarks/teacher_cost.py`` measures them.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from shelf_env.baselines.heuristics import DistanceHeuristic, ObservationView, PickHeuristic
from shelf_env.privileged.lookahead import STAT_KEYS, LookaheadHeuristic, digest, in_fork

#: `PlanningTeacher.stats`: the lookahead's counters, plus the rollouts run and every env action spent
#: (probes, rollout steps and the probes inside rollouts).
PLANNING_STAT_KEYS = (*STAT_KEYS, "planned", "rollouts", "actions")


def unsorted_value(unsorted: int, gamma: float) -> float:
    """The optimistic value of a state with ``unsorted`` objects out of their regions: one action each."""
    return -(1.0 - gamma ** unsorted) / (1.0 - gamma)


def rollout(env: gym.Env, first_action: int, horizon: int, gamma: float,
            base: type[PickHeuristic] = DistanceHeuristic) -> dict[str, Any]:
    """In a forked copy: ``first_action``, then the one-step lookahead on ``base`` until ``horizon``
    actions in all or the episode ends. Returns ``score`` (see the module docstring), ``steps``,
    ``actions`` (env actions spent, probes included), ``success`` and ``invalid``."""

    def play(env_copy: Any) -> dict[str, Any]:
        obs, reward, terminated, truncated, info = env_copy.step(int(first_action))
        score, discount, steps = float(reward), gamma, 1
        policy = LookaheadHeuristic(env_copy, base)
        while not (terminated or truncated) and steps < horizon:
            obs, reward, terminated, truncated, info = env_copy.step(int(policy.predict(obs)[0]))
            score += discount * float(reward)
            discount *= gamma
            steps += 1
        if not terminated:
            score += discount * unsorted_value(int(info["num_objects"]) - int(info["num_sorted"]), gamma)
        return {"score": score, "steps": steps, "actions": steps + policy.stats["probes"],
                "success": bool(info["is_success"]), "invalid": bool(terminated and not info["is_success"])}

    return in_fork(env, play, f"rolling out action {first_action}")


class PlanningTeacher(LookaheadHeuristic):
    """H-d's candidates judged by rollouts of the one-step lookahead (module docstring); policy name
    ``"h-d-planner"``. ``value`` is the last decision's score (None where it had no safe candidate)."""

    def __init__(self, env: gym.Env, horizon: int = 3, max_candidates: int = 6, gamma: float = 0.9,
                 base: type[PickHeuristic] = DistanceHeuristic) -> None:
        super().__init__(env, base)
        if horizon < 1 or max_candidates < 1 or not 0 < gamma < 1:
            raise ValueError(f"need horizon >= 1, max_candidates >= 1 and 0 < gamma < 1, got {horizon}, "
                             f"{max_candidates} and {gamma}")
        self.horizon, self.max_candidates, self.gamma = int(horizon), int(max_candidates), float(gamma)
        self.stats = dict.fromkeys(PLANNING_STAT_KEYS, 0)
        self.value: float | None = None

    def _probe(self, action: int) -> Any:
        self.stats["actions"] += 1
        return super()._probe(action)

    def act_on(self, view: ObservationView, obs: np.ndarray) -> int:
        cells = self.candidates(view)
        prefix = ""
        if not cells:
            cells, prefix = self.uncover_candidates(view), "uncover_"
        self.stats[prefix + "decisions"] += 1
        now = digest(obs)
        safe: list[int] = []
        for action in [self._pick(r, c) for r, c in cells] + (self.push_candidates(view) if self.pushes else []):
            outcome = self._probe(action)
            if outcome.is_success:  # it sorts the scene now: nothing can be better
                self.value = 0.0
                return action
            if outcome.valid and (self.codec.decode(action)[0] == "pick" or outcome.obs_sha256 != now):
                safe.append(action)
                if len(safe) >= self.max_candidates:
                    break
        if not safe:
            self.stats[prefix + "unavoidable"] += 1
            self.value = None
            return self._pick(*cells[0])
        self.stats["planned"] += 1
        scores = []
        for action in safe:
            result = rollout(self.env, action, self.horizon, self.gamma, type(self.base))
            self.stats["rollouts"] += 1
            self.stats["actions"] += int(result["actions"])
            scores.append(float(result["score"]))
        best = int(np.argmax(scores))  # the first of the best: the lookahead's order breaks ties
        self.stats[prefix + "vetoes"] += int(safe[best] != safe[0])
        self.value = scores[best]
        return safe[best]
