"""`CurriculumCallback`: grow the number of objects N when the agent masters the current N (§IV-D.3).

The callback reads ``info["is_success"]`` at episode ends over the last ``window`` episodes of the
current stage. When the rate exceeds ``threshold`` and N < ``max_value`` it raises N by one on
every sub-env (``env.env_method(setter, N)``), restarts the algorithm's ε schedule and empties the
window. The env applies the new N at its next reset; episodes that were already running when N
changed are not counted for the new stage. The stage lives in ``model.curriculum_state``, which is
saved in the model's zip, so a loaded model resumes at the stage (and ε) where it stopped.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

#: Paper's curriculum (§IV-D.3): start at one object, 50-episode window, > 90 %, up to 8 objects.
START_VALUE = 1
MAX_VALUE = 8
WINDOW = 50
THRESHOLD = 0.9


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
    :param verbose: 1 prints each stage change.
    """

    def __init__(
        self,
        start_value: int = START_VALUE,
        max_value: int = MAX_VALUE,
        window: int = WINDOW,
        threshold: float = THRESHOLD,
        setter: str = "set_num_objects",
        min_stage_timesteps: int = 0,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        if not 1 <= start_value <= max_value:
            raise ValueError(f"need 1 <= start_value <= max_value, got {start_value} and {max_value}")
        if window < 1 or not 0.0 <= threshold <= 1.0:
            raise ValueError(f"need window >= 1 and 0 <= threshold <= 1, got {window} and {threshold}")
        self.start_value = start_value
        self.max_value = max_value
        self.window = window
        self.threshold = threshold
        self.setter = setter
        self.min_stage_timesteps = int(min_stage_timesteps)
        self.value = start_value
        self.outcomes: deque[bool] = deque(maxlen=window)
        self.history: list[list[int]] = []
        self._stale = np.zeros(0, dtype=bool)

    def _init_callback(self) -> None:
        state = getattr(self.model, "curriculum_state", None)
        if state:
            self.value = int(state["value"])
            self.outcomes = deque((bool(x) for x in state["outcomes"]), maxlen=self.window)
            self.history = [[int(t), int(n)] for t, n in state["history"]]
        else:
            self.value = self.start_value
            self.outcomes.clear()
            self.history = [[self.model.num_timesteps, self.value]]
        self._stale = np.zeros(self.training_env.num_envs, dtype=bool)
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
                self._stale[i] = False
            elif "is_success" in info:
                self.outcomes.append(bool(info["is_success"]))
                changed = True
        if (
            self.value < self.max_value
            and len(self.outcomes) == self.window
            and float(np.mean(self.outcomes)) > self.threshold
            and self.model.num_timesteps - self.history[-1][0] >= self.min_stage_timesteps
        ):
            self._advance()
        self.logger.record("curriculum/num_objects", self.value)
        if changed:  # _advance saves its own change
            self._save_state()
        return True

    def _advance(self) -> None:
        self.value += 1
        self.outcomes.clear()
        self.training_env.env_method(self.setter, self.value)
        # Episodes in progress (and ones auto-reset this very step) were drawn with the old N.
        self._stale[:] = True
        self.model.restart_exploration()  # type: ignore[attr-defined]
        self.history.append([self.model.num_timesteps, self.value])
        self._save_state()
        if self.verbose:
            print(f"curriculum: N = {self.value} at step {self.model.num_timesteps}")

    @property
    def success_rate(self) -> float:
        """Success over the current stage's window so far (nan before the first counted episode)."""
        return float(np.mean(self.outcomes)) if self.outcomes else float("nan")

    def _save_state(self) -> None:
        state: dict[str, Any] = {
            "value": self.value,
            "outcomes": list(self.outcomes),
            "history": [list(h) for h in self.history],
        }
        self.model.curriculum_state = state  # type: ignore[attr-defined]
