"""`HindsightRelabelReplayBuffer`: a replay buffer that also stores the env's relabelled transitions.

Hindsight protocol (§IV-D.3, Fig. 8). The buffer knows nothing about the env; the env opts in by
adding, to the ``info`` of a step whose end state would be a goal under some other class
assignment, an entry

    info["relabelled"] = {"obs": o_t*, "next_obs": o_{t+1}*, "reward": r*, "terminated": bool}

with both observations already re-rendered under that assignment (same shape and dtype as the
observation space). The buffer then stores the relabelled transition, with the executed action,
right after the original one. Envs that never set the key get a plain replay buffer.

Storage is flat — one transition per slot whatever the number of envs — because a relabelled
transition belongs to one sub-env only. Pickling (``save_replay_buffer``) writes only the filled
part of the arrays, so checkpoints of a young buffer stay small.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer

#: The info key of the hindsight protocol.
RELABEL_KEY = "relabelled"
_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class HindsightRelabelReplayBuffer(ReplayBuffer):
    """Replay buffer of ``buffer_size`` transitions that adds ``info["relabelled"]`` transitions.

    :param buffer_size: total number of transitions kept (over all envs, relabelled ones included).
    :param observation_space: the env's observation space.
    :param action_space: the env's action space.
    :param device: where sampled batches go.
    :param n_envs: number of parallel envs whose steps ``add`` receives.
    :param optimize_memory_usage: not supported (relabelled transitions break the obs/next_obs chain).
    :param handle_timeout_termination: time-limit truncations are stored as non-terminal.
    """

    def __init__(
        self,
        buffer_size: int,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        device: th.device | str = "auto",
        n_envs: int = 1,
        optimize_memory_usage: bool = False,
        handle_timeout_termination: bool = True,
    ) -> None:
        if optimize_memory_usage:
            raise ValueError(
                "HindsightRelabelReplayBuffer does not support optimize_memory_usage=True: "
                "relabelled transitions are not followed by their next observation"
            )
        super().__init__(
            buffer_size, observation_space, action_space, device, n_envs=1,
            optimize_memory_usage=False, handle_timeout_termination=handle_timeout_termination,
        )
        self.n_source_envs = n_envs
        self.n_relabelled = 0

    def add(
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        """Store each env's transition, then its relabelled twin if the env reported one."""
        obs, next_obs = np.asarray(obs), np.asarray(next_obs)
        action, reward, done = np.asarray(action), np.asarray(reward), np.asarray(done)
        for i, info in enumerate(infos):
            super().add(obs[i:i + 1], next_obs[i:i + 1], action[i:i + 1], reward[i:i + 1], done[i:i + 1], [info])
            relabelled = info.get(RELABEL_KEY)
            if relabelled is not None:
                self._add_relabelled(relabelled, action[i:i + 1])

    def _add_relabelled(self, relabelled: dict[str, Any], action: np.ndarray) -> None:
        try:
            r_obs = np.asarray(relabelled["obs"], dtype=self.observations.dtype)
            r_next = np.asarray(relabelled["next_obs"], dtype=self.observations.dtype)
            r_reward = float(relabelled["reward"])
            r_done = float(bool(relabelled["terminated"]))
        except (KeyError, TypeError) as err:
            raise ValueError(
                f'info["{RELABEL_KEY}"] must be a dict with keys obs, next_obs, reward, terminated; got {err!r}'
            ) from err
        for name, array in (("obs", r_obs), ("next_obs", r_next)):
            if array.shape != self.obs_shape:
                raise ValueError(
                    f'info["{RELABEL_KEY}"]["{name}"] has shape {array.shape}, '
                    f"expected the observation shape {self.obs_shape}"
                )
        super().add(r_obs[None], r_next[None], action, np.array([r_reward]), np.array([r_done]), [{}])
        self.n_relabelled += 1

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        stored = self.buffer_size if self.full else self.pos
        for name in _ARRAYS:
            state[name] = state[name][:stored]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        for name in _ARRAYS:
            stored = state[name]
            full = np.zeros((state["buffer_size"], *stored.shape[1:]), dtype=stored.dtype)
            full[: len(stored)] = stored
            state[name] = full
        self.__dict__.update(state)
