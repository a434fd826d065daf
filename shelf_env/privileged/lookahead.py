"""Privileged one-step lookahead: a heuristic that sees, before acting, which picks drop an object.

Issue 10 asks whether the falls that end most episodes from N = 5 on could be avoided by a better
choice of pick, or are the env's (no policy could avoid them). `LookaheadHeuristic` answers the
one-step version of that question exactly. At every step it takes its base heuristic's (H-a or
H-d) candidate picks, one per visible unsorted object (that object's best-scoring graspable cell),
best first, and tries each in an exact copy of the env: `probe_step` forks this process, and
PyBullet's DIRECT physics server lives in the process's memory, so the child continues exactly
the simulation the parent would (Bullet is deterministic given the same state). It takes the first
candidate whose step leaves the scene valid (nothing fell, everything at rest); when every
candidate would end the episode invalid, it takes the base heuristic's own choice.

When every visible object looks sorted, the base heuristic uncovers: it picks the front-most
object. The lookahead then probes that pick first and every other visible object's front-most cell
after it, front first, in the same way. When every candidate pick is invalid, it probes pushes
(`LookaheadHeuristic.push_candidates`: two per visible object, from either side at its middle row)
and takes the first that leaves the scene valid *and* changes the observation (a push that moves
nothing would only repeat the deadlock).

So with ``max_probes`` covering every candidate, an episode of the lookahead policy ends invalid only
at a step where *every* candidate pick and push would have: `stats` (per episode in the evaluation
records, ``policy_stats``) says whether that step was a sorting step (``unavoidable``) or an
uncovering one (``uncover_unavoidable``). Its fall rate on the evaluation scenes bounds from above
the rate of falls that no choice among these actions at that step avoids. It is a diagnostic and a
privileged teacher, not a baseline of the paper: it reads the simulator, which a real robot cannot
fork.

Limits: POSIX only (``os.fork``), PyBullet in DIRECT mode only (a GUI or shared-memory server is not
copied by a fork), one probe costs one env action, and the probe does not look past the step (a pick
that is safe now but leaves a trap is not seen).
"""

from __future__ import annotations

import hashlib
import os
import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import pybullet as pb

from sb3_pixeldqn.buffers import CORRECTION_KEY
from shelf_env.baselines.heuristics import (
    AccessibilityHeuristic,
    DistanceHeuristic,
    ObservationView,
    PickHeuristic,
    front_most,
)
from shelf_env.env import ShelfSortEnv

#: `LookaheadHeuristic.stats`: steps decided among visible unsorted objects' picks (``decisions``)
#: or, when every visible object looked sorted, among uncovering picks (``uncover_decisions``); of
#: those, how many vetoed the base heuristic's choice (``vetoes``), how many found every candidate
#: pick invalid but a push valid (``push_rescues``, either kind of step) and how many found every
#: candidate pick and push invalid (``unavoidable``); and the probes (forked steps) spent on all.
STAT_KEYS = ("decisions", "vetoes", "unavoidable", "uncover_decisions", "uncover_vetoes", "uncover_unavoidable",
             "push_rescues", "probes")


@dataclass(frozen=True)
class Outcome:
    """What `ShelfSortEnv.step` of one action would return, as seen by a forked copy of the env."""

    reward: float
    terminated: bool
    fell: bool
    is_success: bool
    obs_sha256: str  # digest of the next observation, to check that the copy is exact
    #: the next observation itself (None where an Outcome is made by hand); not compared
    next_obs: np.ndarray | None = field(default=None, compare=False, repr=False)
    #: objects in their own class's region after the step (``info["num_sorted"]``); None where made by hand
    num_sorted: int | None = None

    @property
    def valid(self) -> bool:
        """Nothing fell and everything came to rest (the task's rules, `shelf_env.world.task`): the step did not
        end the episode, or ended it sorted (read from the flags, not the reward, which the env's
        ``invalid_reward`` may change)."""
        return not self.terminated or self.is_success


def digest(obs: np.ndarray) -> str:
    """sha256 of an observation's bytes (`Outcome.obs_sha256`)."""
    return hashlib.sha256(np.ascontiguousarray(obs).tobytes()).hexdigest()


def in_fork(env: gym.Env, work: Callable[[Any], dict[str, Any]], what: str) -> dict[str, Any]:
    """``work(base env)`` run in a forked copy of this process, which holds the env's PyBullet DIRECT
    physics, so the copy continues exactly the simulation the parent would; its report (a picklable
    dict) comes back through a pipe and ``env`` is left untouched. ``what`` names the work in errors."""
    base = env.unwrapped
    if not isinstance(base, ShelfSortEnv):
        raise ValueError(f"probe_step needs a ShelfSort-v0 env, got {type(base).__name__}")
    if not hasattr(os, "fork"):
        raise RuntimeError("probe_step forks the process (os.fork), which this platform does not have")
    if base.client is None:
        raise RuntimeError("probe_step: the env is closed")
    method = pb.getConnectionInfo(physicsClientId=base.client).get("connectionMethod")
    if method != pb.DIRECT:
        raise RuntimeError(f"probe_step needs PyBullet in DIRECT mode (the physics in this process); the env's "
                           f"client uses connection method {method}")
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # the copy: work, report, leave without running any of the parent's exit handlers
        status = 0
        try:
            os.close(read_fd)
            payload = work(base)
        except BaseException as err:  # noqa: BLE001  (reported to the parent, which raises it)
            payload, status = {"error": f"{type(err).__name__}: {err}"}, 1
        data = pickle.dumps(payload)  # this process's own copy: a trusted pickle
        while data:
            data = data[os.write(write_fd, data):]
        os._exit(status)
    os.close(write_fd)
    chunks = []
    with os.fdopen(read_fd, "rb") as pipe:
        while chunk := pipe.read(65536):
            chunks.append(chunk)
    os.waitpid(pid, 0)
    if not chunks:
        raise RuntimeError(f"probe_step: the forked copy {what} died without a report")
    report = pickle.loads(b"".join(chunks))  # noqa: S301  (written by our own fork above)
    if "error" in report:
        raise RuntimeError(f"probe_step: {what} in the forked copy failed: {report['error']}")
    return report


def probe_step(env: gym.Env, action: int) -> Outcome:
    """The `Outcome` of ``env.step(action)``, computed in a forked copy; ``env`` is left untouched."""

    def step(base: Any) -> dict[str, Any]:
        obs, reward, terminated, _, info = base.step(int(action))
        return {"reward": float(reward), "terminated": bool(terminated), "fell": bool(info["fell"]),
                "is_success": bool(info["is_success"]), "num_sorted": int(info["num_sorted"]),
                "obs_sha256": digest(obs), "next_obs": np.asarray(obs)}

    return Outcome(**in_fork(env, step, f"stepping action {action}"))


def probe_outcome(env: gym.Env, action: int) -> Outcome:
    """`probe_step` without the next observation (`ShelfSortEnv.step_outcome`: the copy skips the camera):
    the same reward, flags and sorted count, ``obs_sha256`` empty and ``next_obs`` None. For labels that need
    the outcome alone (the teacher dataset's probes), at 0.55-0.66x `probe_step`'s cost at N = 5..11
    (``benchmarks/probe_cost.py``)."""
    report = in_fork(env, lambda base: base.step_outcome(int(action)), f"stepping action {action}")
    return Outcome(obs_sha256="", **report)


class LookaheadHeuristic(PickHeuristic):
    """A pick heuristic (``base``: H-a or H-d) that vetoes picks the simulator says end the episode
    invalid (see the module docstring); with ``pushes`` (and the env's push primitive) a step where
    every pick is invalid tries pushes before giving up. ``stats`` counts them (`STAT_KEYS`)."""

    def __init__(self, env: gym.Env, base: type[PickHeuristic] = AccessibilityHeuristic,
                 max_probes: int | None = None, pushes: bool = True) -> None:
        super().__init__(env)
        if max_probes is not None and max_probes < 1:
            raise ValueError(f"max_probes must be >= 1 or None (every candidate), got {max_probes}")
        self.env = env
        self.base = base(env)
        self.max_probes = max_probes
        self.pushes = pushes
        self.stats = dict.fromkeys(STAT_KEYS, 0)
        self._probed: list[tuple[int, Outcome]] = []  # the last decision's probes
        self._taken: int | None = None  # and its action

    def _act(self, obs: np.ndarray, allowed: np.ndarray | None = None) -> int:
        self._probed = []
        self._taken = super()._act(obs, allowed)
        return self._taken

    def counterfactuals(self) -> list[tuple[int, float, np.ndarray]]:
        """The actions that the last decision probed and rejected because they would have ended the
        episode invalid (a fall, a scene not at rest), as ``(action, reward, next observation)``,
        exactly what the env's step would have returned. A learner of the demonstrations stores
        them as terminal transitions (`PixelDoubleDQN.collect_demonstrations` with
        ``counterfactuals=True``): they show, in the very state, which picks drop an object, which
        the demonstrated action alone does not. Rejected pushes that kept the scene valid but moved
        nothing are left out (not terminal: their next state's mask is unknown). Empty before the
        first decision and after one that probed nothing (nothing visible); after `predict` of a
        batch, those of its last image."""
        return [(action, outcome.reward, outcome.next_obs) for action, outcome in self._probed
                if outcome.terminated and not outcome.valid and action != self._taken
                and outcome.next_obs is not None]

    def _probe(self, action: int) -> Outcome:
        self.stats["probes"] += 1
        outcome = probe_step(self.env, action)
        self._probed.append((action, outcome))
        return outcome

    def score(self, view: ObservationView) -> np.ndarray:
        return self.base.score(view)

    def candidates(self, view: ObservationView) -> list[tuple[int, int]]:
        """One cell per visible object with a candidate cell: its best-scoring one, best object first."""
        score = self.score(view)
        best: list[tuple[float, int, int]] = []
        for b in np.unique(view.blob[np.isfinite(score)]):
            masked = np.where(view.blob == b, score, -np.inf)
            flat = int(np.argmax(masked))  # first of the blob's best cells in raster order, as `choose` takes
            row, col = divmod(flat, score.shape[1])
            best.append((float(masked[row, col]), row, col))
        best.sort(key=lambda t: (-t[0], t[1] * score.shape[1] + t[2]))
        return [(row, col) for _, row, col in best]

    def uncover_candidates(self, view: ObservationView) -> list[tuple[int, int]]:
        """When every visible object looks sorted: the base's uncovering pick (the front-most object)
        first, then every other visible object's front-most cell, front first."""
        first = front_most(view.graspable)
        others = [front_most(view.graspable & (view.blob == b)) for b in np.unique(view.blob[view.graspable])]
        others.sort(key=lambda rc: (-rc[0], rc[1]))
        return [first] + [rc for rc in others if view.blob[rc] != view.blob[first]]

    def push_candidates(self, view: ObservationView) -> list[int]:
        """Pushes that could free a deadlock (every pick invalid): for each visible object, a push
        from just beside it at its middle row, towards its class's region first, then away;
        unsorted objects first, front first. Empty where the env has no push primitive."""
        if not {"push_left", "push_right"} <= set(self.codec.map_names):
            return []
        gap = self.margin_cells + 1  # start the blade clear of the object's side
        scored = []
        for b in np.unique(view.blob[view.blob >= 0]):
            rows, cols = np.nonzero(view.blob == b)
            row = int(np.median(rows))
            in_row = cols[rows == row]
            rect = view.regions[int(view.object_class[rows[0], cols[0]])]
            towards_left = rect is not None and (rect[2] + rect[3]) / 2 < cols.mean()
            pushes = [("push_left", min(self.cols - 1, int(in_row.max()) + gap)),
                      ("push_right", max(0, int(in_row.min()) - gap))]
            if not towards_left:
                pushes.reverse()
            is_sorted = bool(view.sorted_cells[rows[0], cols[0]])
            scored += [((is_sorted, -int(rows.max()), i), self.codec.encode(name, row, col))
                       for i, (name, col) in enumerate(pushes)]
        return [action for _, action in sorted(scored)]

    def act_on(self, view: ObservationView, obs: np.ndarray) -> int:
        cells = self.candidates(view)
        prefix = ""
        if not cells:  # every visible object looks sorted: probe the uncovering picks instead
            cells, prefix = self.uncover_candidates(view), "uncover_"
        self.stats[prefix + "decisions"] += 1
        for i, (row, col) in enumerate(cells[:self.max_probes]):
            if self._probe(self._pick(row, col)).valid:
                self.stats[prefix + "vetoes"] += int(i > 0)
                return self._pick(row, col)
        if self.pushes:  # every pick probed is invalid: a push that keeps the scene valid and changes it
            now = digest(obs)
            for action in self.push_candidates(view)[:self.max_probes]:
                outcome = self._probe(action)
                if outcome.valid and outcome.obs_sha256 != now:
                    self.stats["push_rescues"] += 1
                    return action
        self.stats[prefix + "unavoidable"] += 1
        return self._pick(*cells[0])


class LookaheadAccessibility(LookaheadHeuristic):
    """H-a with the one-step lookahead (`LookaheadHeuristic`), policy name ``"h-a-lookahead"``."""

    def __init__(self, env: gym.Env, max_probes: int | None = None, pushes: bool = True) -> None:
        super().__init__(env, AccessibilityHeuristic, max_probes, pushes)


class LookaheadDistance(LookaheadHeuristic):
    """H-d with the one-step lookahead (`LookaheadHeuristic`), policy name ``"h-d-lookahead"``."""

    def __init__(self, env: gym.Env, max_probes: int | None = None, pushes: bool = True) -> None:
        super().__init__(env, DistanceHeuristic, max_probes, pushes)


class FallGuard(gym.Wrapper):
    """A privileged supervisor of a learner in training (DAgger-style corrections): every action is
    first tried in a forked copy of the env (`probe_step`); one that would end the episode invalid
    (an object falls, the scene does not come to rest) is replaced by the ``teacher``'s choice (a
    lookahead heuristic, built on the wrapped env) and the step's info reports the correction in
    sb3_pixeldqn's protocol (``info["correction"]``: the vetoed action, what the env's step would
    have returned for it, and the executed action), which `PixelDoubleDQN` stores as a correction.
    Where the teacher finds nothing better (it chooses the same action) the action is executed as
    given. ``stats`` counts steps, corrections and probes (the teacher's included).

    The negatives then sit where the learner's own (ε-)greedy policy goes, which the teacher's
    demonstrations and counterfactuals (one candidate cell per object) do not reach
    (``results/p_s_la/fall_prediction.md``). Training only: it reads the simulator, which a robot
    cannot fork, and costs one extra env action per step (more on a correction).
    """

    def __init__(self, env: gym.Env, teacher: type[LookaheadHeuristic] | None = None) -> None:
        super().__init__(env)
        self.teacher = (teacher or LookaheadDistance)(env)
        self._steps = self._corrections = 0

    @property
    def stats(self) -> dict[str, int]:
        """Steps, corrections and probes: one per step plus the teacher's (it probes only for the guard)."""
        return {"steps": self._steps, "corrections": self._corrections,
                "probes": self._steps + self.teacher.stats["probes"]}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        action = int(action)
        self._steps += 1
        outcome = probe_step(self.env, action)
        executed = action
        if not outcome.valid:
            state = self.env.unwrapped.observation  # type: ignore[attr-defined]  # probe_step checked the env
            executed = int(self.teacher.predict(state, deterministic=True)[0])
        obs, reward, terminated, truncated, info = self.env.step(executed)
        if executed != action:
            self._corrections += 1
            info = {**info, CORRECTION_KEY: {"action": action, "executed": executed, "reward": outcome.reward,
                                             "next_obs": outcome.next_obs, "terminated": outcome.terminated}}
        return obs, float(reward), terminated, truncated, info
