"""`CurriculumCallback`: grow the number of objects N when the agent masters the current N (§IV-D.3).

The callback reads ``info["is_success"]`` at episode ends over the last ``window`` episodes of the
current stage. When the rate exceeds ``threshold`` and N < ``max_value`` it raises N by one on
every sub-env (``env.env_method(setter, N)``), restarts the algorithm's ε schedule and empties the
window. The env applies the new N at its next reset; episodes that were already running when N
changed are not counted for the new stage (with an `ActorVecEnv`, neither are the episodes among
its transitions not consumed yet). The stage lives in ``model.curriculum_state``, which is
saved in the model's zip, so a loaded model resumes at the stage (and ε) where it stopped.

Two promotion rules:

- ``gate="training"`` (the paper's): success over the last ``window`` training episodes, which
  are ε-greedy. With masked exploration those flatter the policy: a random allowed pick is often
  right, so a stage can pass before the greedy policy has learned anything.
- ``gate="greedy"`` (recommended): every ``eval_every`` steps the deterministic policy — masked
  with the eval env's ``action_masks()`` when it has them and the model ``acts_masked`` — plays
  ``eval_episodes`` fresh scenes of ``eval_env`` at the current N; the stage passes when at least
  ``threshold`` of them succeed. Scenes come from reset seeds drawn from ``eval_seed``'s own
  stream, never from the training env's.

Either rule can be given a stage cap, ``max_stage_timesteps``: a stage that has not passed after
that many env steps is promoted anyway (its steps are listed in ``capped``). It is for stages
whose gate a policy cannot pass for reasons outside its control, e.g. an env where objects fall
out in a share of episodes that no policy can avoid, so that a success threshold meant for
easier settings would hold the curriculum at one N for the rest of the budget. The cap bounds the
last stage too: once N = ``max_value`` has trained ``max_stage_timesteps`` steps the curriculum
is over (``finished`` holds that step) and the callback stops training, so a capped curriculum has
a length of its own rather than the wall-clock budget's; a resumed run stops at its first step.

With an ``eval_env`` the greedy checks run under either gate (``greedy_history``, logged as
``curriculum/greedy_success``): the learning curve of the policy that will be shipped.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_pixeldqn.actor import ActorVecEnv

#: Paper's curriculum (§IV-D.3): start at one object, 50-episode window, > 90 %, up to 8 objects.
START_VALUE = 1
MAX_VALUE = 8
WINDOW = 50
THRESHOLD = 0.9
GATES = ("training", "greedy")
#: Greedy gate defaults: sized so that a check at N = 3 costs ~15 s of a 2-core machine.
EVAL_EVERY = 500
EVAL_EPISODES = 20


def curriculum_over(state: dict[str, Any], num_timesteps: int, max_value: int, max_stage_timesteps: int) -> bool:
    """Whether a saved curriculum ``state`` is over at ``num_timesteps``: its last stage (N =
    ``max_value``) has trained ``max_stage_timesteps`` steps (never without a cap)."""
    return bool(
        max_stage_timesteps
        and state.get("value") == max_value
        and num_timesteps - int(state["history"][-1][0]) >= max_stage_timesteps
    )


class CurriculumCallback(BaseCallback):
    """Success-gated curriculum over an env parameter (by default the number of objects).

    :param start_value: N of the first stage (ignored when the model carries a saved stage).
    :param max_value: last N.
    :param window: episodes of the current stage over which success is averaged.
    :param threshold: the success rate must exceed this to advance.
    :param setter: name of the env method that sets N for the following episodes.
    :param min_stage_timesteps: env steps a stage lasts at least (0: as the paper). Setting it to
        the algorithm's ``exploration_timesteps`` makes a stage advance only once ε has decayed,
        so that the success that promotes it is the policy's rather than exploration's.
    :param max_stage_timesteps: env steps after which a stage that has not passed its gate is
        promoted anyway (0: never, as the paper); at least ``min_stage_timesteps`` when set. The
        last stage ends after as many steps, and with it the training (``finished``).
    :param gate: ``"training"`` (the paper's rule) or ``"greedy"`` (see the module docstring).
    :param eval_env: a Gymnasium env (not vectorised) with the ``setter`` method, for greedy checks
        (needed by the greedy gate; optional under the training gate, where they only log).
    :param eval_every: env steps between greedy checks.
    :param eval_episodes: episodes per greedy check.
    :param eval_seed: seed of the greedy checks' scene stream.
    :param eval_max_actions: a greedy-check episode still running after this many actions counts as
        failed and is cut; an int, or a function of the stage's value (e.g. more actions for more
        objects), or None (the env's own limit). A looping policy then costs little to check.
    :param verbose: 1 prints each stage change and greedy check.
    """

    def __init__(
        self,
        start_value: int = START_VALUE,
        max_value: int = MAX_VALUE,
        window: int = WINDOW,
        threshold: float = THRESHOLD,
        setter: str = "set_num_objects",
        min_stage_timesteps: int = 0,
        max_stage_timesteps: int = 0,
        gate: str = "training",
        eval_env: gym.Env | None = None,
        eval_every: int = EVAL_EVERY,
        eval_episodes: int = EVAL_EPISODES,
        eval_seed: int = 0,
        eval_max_actions: int | Callable[[int], int] | None = None,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        if gate not in GATES:
            raise ValueError(f"gate must be one of {GATES}, got {gate!r}")
        if gate == "greedy" and eval_env is None:
            raise ValueError('gate="greedy" needs an eval_env (a Gymnasium env like the training one)')
        if eval_every < 1 or eval_episodes < 1:
            raise ValueError(f"need eval_every >= 1 and eval_episodes >= 1, got {eval_every} and {eval_episodes}")
        if not 1 <= start_value <= max_value:
            raise ValueError(f"need 1 <= start_value <= max_value, got {start_value} and {max_value}")
        if window < 1 or not 0.0 <= threshold <= 1.0:
            raise ValueError(f"need window >= 1 and 0 <= threshold <= 1, got {window} and {threshold}")
        self.start_value = start_value
        self.max_value = max_value
        self.window = window
        self.threshold = threshold
        self.setter = setter
        if min_stage_timesteps < 0 or max_stage_timesteps < 0 or 0 < max_stage_timesteps < min_stage_timesteps:
            raise ValueError("need min_stage_timesteps >= 0 and max_stage_timesteps 0 (no cap) or >= "
                             f"min_stage_timesteps, got {min_stage_timesteps} and {max_stage_timesteps}")
        self.min_stage_timesteps = int(min_stage_timesteps)
        self.max_stage_timesteps = int(max_stage_timesteps)
        self.gate = gate
        self.eval_env = eval_env
        self.eval_every = int(eval_every)
        self.eval_episodes = int(eval_episodes)
        self.eval_rng = np.random.default_rng(eval_seed)
        self.eval_max_actions = eval_max_actions
        #: Greedy checks so far: [timestep, N, success rate].
        self.greedy_history: list[list[float]] = []
        self._last_check = 0
        self.value = start_value
        self.outcomes: deque[bool] = deque(maxlen=window)
        self.history: list[list[int]] = []
        #: Env steps at which a stage was promoted by ``max_stage_timesteps`` rather than its gate.
        self.capped: list[int] = []
        #: Env step at which the last stage reached ``max_stage_timesteps`` (None: not yet).
        self.finished: int | None = None
        self._stale = np.zeros(0, dtype=np.int64)

    def _init_callback(self) -> None:
        state = getattr(self.model, "curriculum_state", None)
        if state:
            self.value = int(state["value"])
            self.outcomes = deque((bool(x) for x in state["outcomes"]), maxlen=self.window)
            self.history = [[int(t), int(n)] for t, n in state["history"]]
            self.greedy_history = [list(h) for h in state.get("greedy_history", [])]
            self.capped = [int(t) for t in state.get("capped", [])]
            self.finished = None if state.get("finished") is None else int(state["finished"])
            if "eval_rng" in state:
                self.eval_rng.bit_generator.state = state["eval_rng"]
        else:
            self.value = self.start_value
            self.outcomes.clear()
            self.history = [[self.model.num_timesteps, self.value]]
            self.capped = []
            self.finished = None
        if self.finished is not None and not self.over():
            self.finished = None  # resumed with a longer cap: the last stage goes on
        self._stale = np.zeros(self.training_env.num_envs, dtype=np.int64)  # episode ends to leave out
        self._last_check = int(self.greedy_history[-1][0]) if self.greedy_history else self.model.num_timesteps
        self._save_state()

    def _on_training_start(self) -> None:
        # Start every sub-env at the stage's N right away. At this point no transition is pending,
        # so replacing the algorithm's last observation is safe.
        self.training_env.env_method(self.setter, self.value)
        self.model._last_obs = self.training_env.reset()  # type: ignore[assignment]
        vec_normalize = self.model.get_vec_normalize_env()
        if vec_normalize is not None:
            self.model._last_original_obs = vec_normalize.get_original_obs()
        self.model._last_episode_starts = np.ones(self.training_env.num_envs, dtype=bool)
        self.logger.record("curriculum/num_objects", self.value)

    def _on_step(self) -> bool:
        changed = False
        for i, (done, info) in enumerate(zip(self.locals["dones"], self.locals["infos"])):
            if not done:
                continue
            if self._stale[i]:
                self._stale[i] -= 1
            elif "is_success" in info:
                self.outcomes.append(bool(info["is_success"]))
                changed = True
        long_enough = self.model.num_timesteps - self.history[-1][0] >= self.min_stage_timesteps
        if self.eval_env is not None and self.model.num_timesteps - self._last_check >= self.eval_every:
            # greedy checks run whenever there is an eval env (a learning curve); they promote only
            # under the greedy gate
            self._last_check = self.model.num_timesteps
            rate = self.greedy_success()
            self.greedy_history.append([self.model.num_timesteps, self.value, rate])
            self.logger.record("curriculum/greedy_success", rate)
            if self.verbose:
                print(f"curriculum: greedy success {rate:.0%} at N = {self.value}, step {self.model.num_timesteps}",
                      flush=True)
            if self.gate == "greedy" and self.value < self.max_value and rate >= self.threshold and long_enough:
                self._advance()
            changed = True
        if (
            self.gate == "training"
            and self.value < self.max_value
            and len(self.outcomes) == self.window
            and float(np.mean(self.outcomes)) > self.threshold
            and long_enough
        ):
            self._advance()
        if (
            self.max_stage_timesteps
            and self.value < self.max_value
            and self.model.num_timesteps - self.history[-1][0] >= self.max_stage_timesteps
        ):
            self.capped.append(self.model.num_timesteps)
            if self.verbose:
                print(f"curriculum: N = {self.value} not passed in {self.max_stage_timesteps} steps; "
                      "promoted by the stage cap")
            self._advance()
        self.logger.record("curriculum/num_objects", self.value)
        over = self.over()
        if over and self.finished is None:
            self.finished = self.model.num_timesteps
            changed = True
            if self.verbose:
                print(f"curriculum: the last stage, N = {self.value}, has trained {self.max_stage_timesteps} "
                      f"steps; the curriculum is over at step {self.finished}", flush=True)
        if changed:  # _advance saves its own change
            self._save_state()
        return not over

    def over(self) -> bool:
        """True once the last stage has trained ``max_stage_timesteps`` steps (never without a cap)."""
        state = {"value": self.value, "history": self.history}
        return curriculum_over(state, self.model.num_timesteps, self.max_value, self.max_stage_timesteps)

    def _advance(self) -> None:
        self.value += 1
        self.outcomes.clear()
        self.training_env.env_method(self.setter, self.value)
        # Episodes in progress (and ones auto-reset this very step) were drawn with the old N; with
        # an actor process, so were the episodes ending among its transitions not consumed yet.
        self._stale[:] = 1
        if isinstance(self.training_env, ActorVecEnv):
            self._stale += self.training_env.pending_episode_ends()
        self.model.restart_exploration()  # type: ignore[attr-defined]
        self.history.append([self.model.num_timesteps, self.value])
        self._save_state()
        if self.verbose:
            print(f"curriculum: N = {self.value} at step {self.model.num_timesteps}")

    def greedy_success(self) -> float:
        """Success rate of the deterministic (masked) policy on ``eval_episodes`` fresh scenes at the current N."""
        env = self.eval_env
        assert env is not None
        env.get_wrapper_attr(self.setter)(self.value)
        # as the model acts: with the env's masks unless it was trained without them (acts_masked)
        has_masks = env.has_wrapper_attr("action_masks") and getattr(self.model, "acts_masked", True)
        limit = self.eval_max_actions(self.value) if callable(self.eval_max_actions) else self.eval_max_actions
        successes = 0
        for _ in range(self.eval_episodes):
            obs, info = env.reset(seed=int(self.eval_rng.integers(2**31)))
            done, actions = False, 0
            while not done:
                masks = np.asarray(env.get_wrapper_attr("action_masks")()) if has_masks else None
                action, _ = self.model.predict(obs, deterministic=True, action_masks=masks)  # type: ignore[call-arg]
                obs, _, terminated, truncated, info = env.step(int(np.asarray(action).reshape(-1)[0]))
                actions += 1
                done = terminated or truncated
                if not done and limit is not None and actions >= limit:
                    info = {"is_success": False}
                    done = True
            successes += bool(info.get("is_success"))
        return successes / self.eval_episodes

    @property
    def success_rate(self) -> float:
        """Success over the current stage's window so far (nan before the first counted episode)."""
        return float(np.mean(self.outcomes)) if self.outcomes else float("nan")

    def _save_state(self) -> None:
        state: dict[str, Any] = {
            "value": self.value,
            "outcomes": list(self.outcomes),
            "history": [list(h) for h in self.history],
            "greedy_history": [list(h) for h in self.greedy_history],
            "capped": list(self.capped),
            "finished": self.finished,
            "eval_rng": self.eval_rng.bit_generator.state,
        }
        self.model.curriculum_state = state  # type: ignore[attr-defined]


class QMapImageCallback(BaseCallback):
    """Log what the network values as TensorBoard images, every ``every`` env steps.

    For the current observation of the first training env: ``images/observation`` (its first three
    channels as RGB, the env's view) and one ``images/q_<map>`` per Q-map (pick, push_0, push_180,
    ...), each min-max normalised to [0, 1] (bright = high value). Images reach TensorBoard at the
    logger's next dump (every ``log_interval`` episodes), so ``every`` should be a multiple of the
    episode length or larger. Text outputs (stdout, csv, json) never see them.

    :param every: env steps between two logged sets of images (>= 1).
    """

    def __init__(self, every: int = 1000, verbose: int = 0) -> None:
        super().__init__(verbose)
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        self.every = int(every)
        self._last = 0

    def _on_step(self) -> bool:
        if self.num_timesteps - self._last >= self.every:
            self._last = self.num_timesteps
            self.log_images()
        return True

    def log_images(self) -> None:
        """Record the observation and Q-map images of the first env's current observation."""
        from stable_baselines3.common.logger import Image

        obs = np.asarray(self.model._last_obs)[0]
        q = self.model.policy.q_map_values(obs)  # type: ignore[operator]
        exclude = ("stdout", "log", "json", "csv")
        self.logger.record("images/observation", Image(np.ascontiguousarray(obs[:3]), "CHW"), exclude=exclude)
        names = [f"{name}_{degrees}" if degrees else name for name, degrees in self.model.policy.maps]  # type: ignore[union-attr]
        for name, q_map in zip(names, q):
            span = float(q_map.max() - q_map.min())
            scaled = (q_map - q_map.min()) / span if span > 0 else np.zeros_like(q_map)
            self.logger.record(f"images/q_{name}", Image(scaled.astype(np.float32), "HW"), exclude=exclude)
