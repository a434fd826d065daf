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

So with ``max_probes`` covering every candidate, an episode of the lookahead policy ends with a fall
only where *every* pick of a visible unsorted object would have dropped something, or where every
visible object looks sorted (the base heuristic's one uncovering pick, the front-most object, is
then taken unprobed): its fall rate on the evaluation scenes bounds from above the rate of falls
that no choice among these picks at that step avoids. It is a
diagnostic and a privileged teacher, not a baseline of the paper: it reads the simulator, which a
real robot cannot fork.

Limits: POSIX only (``os.fork``), PyBullet in DIRECT mode only (a GUI or shared-memory server is not
copied by a fork), one probe costs one env action, and the probe does not look past the step (a pick
that is safe now but leaves a trap is not seen).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.env import ShelfSortEnv
from shelf_env.heuristics import AccessibilityHeuristic, DistanceHeuristic, ObservationView, PickHeuristic


@dataclass(frozen=True)
class Outcome:
    """What `ShelfSortEnv.step` of one action would return, as seen by a forked copy of the env."""

    reward: float
    terminated: bool
    fell: bool
    is_success: bool
    obs_sha256: str  # digest of the next observation, to check that the copy is exact

    @property
    def valid(self) -> bool:
        """Nothing fell and everything came to rest (the task's rules, `shelf_env.task`)."""
        return self.reward != params.REWARD_INVALID


def probe_step(env: gym.Env, action: int) -> Outcome:
    """The `Outcome` of ``env.step(action)``, computed in a forked copy; ``env`` is left untouched."""
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
    if pid == 0:  # the copy: step, report, leave without running any of the parent's exit handlers
        status = 0
        try:
            os.close(read_fd)
            obs, reward, terminated, _, info = base.step(int(action))
            payload = {"reward": float(reward), "terminated": bool(terminated), "fell": bool(info["fell"]),
                       "is_success": bool(info["is_success"]),
                       "obs_sha256": hashlib.sha256(np.ascontiguousarray(obs).tobytes()).hexdigest()}
        except BaseException as err:  # noqa: BLE001  (reported to the parent, which raises it)
            payload, status = {"error": f"{type(err).__name__}: {err}"}, 1
        data = json.dumps(payload).encode()
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
        raise RuntimeError(f"probe_step: the forked copy stepping action {action} died without a report")
    report = json.loads(b"".join(chunks))
    if "error" in report:
        raise RuntimeError(f"probe_step: stepping action {action} in the forked copy failed: {report['error']}")
    return Outcome(**report)


class LookaheadHeuristic(PickHeuristic):
    """A pick heuristic (``base``: H-a or H-d) that vetoes picks the simulator says end the episode
    invalid (see the module docstring). ``stats`` counts decisions, probes, vetoes (the base's choice
    would have been invalid and another candidate was not) and unavoidable steps (every candidate
    probed was invalid)."""

    def __init__(self, env: gym.Env, base: type[PickHeuristic] = AccessibilityHeuristic,
                 max_probes: int | None = None) -> None:
        super().__init__(env)
        if max_probes is not None and max_probes < 1:
            raise ValueError(f"max_probes must be >= 1 or None (every candidate), got {max_probes}")
        self.env = env
        self.base = base(env)
        self.max_probes = max_probes
        self.stats = {"decisions": 0, "probes": 0, "vetoes": 0, "unavoidable": 0}

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

    def choose(self, view: ObservationView) -> tuple[int, int]:
        cells = self.candidates(view)
        if not cells:
            return super().choose(view)
        self.stats["decisions"] += 1
        for i, (row, col) in enumerate(cells[:self.max_probes]):
            self.stats["probes"] += 1
            if probe_step(self.env, self._pick(row, col)).valid:
                self.stats["vetoes"] += int(i > 0)
                return row, col
        self.stats["unavoidable"] += 1
        return cells[0]


class LookaheadAccessibility(LookaheadHeuristic):
    """H-a with the one-step lookahead (`LookaheadHeuristic`), policy name ``"h-a-lookahead"``."""

    def __init__(self, env: gym.Env, max_probes: int | None = None) -> None:
        super().__init__(env, AccessibilityHeuristic, max_probes)


class LookaheadDistance(LookaheadHeuristic):
    """H-d with the one-step lookahead (`LookaheadHeuristic`), policy name ``"h-d-lookahead"``."""

    def __init__(self, env: gym.Env, max_probes: int | None = None) -> None:
        super().__init__(env, DistanceHeuristic, max_probes)
