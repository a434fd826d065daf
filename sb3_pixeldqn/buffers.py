"""`HindsightRelabelReplayBuffer`: the replay buffer of `PixelDoubleDQN`.

Beyond SB3's `ReplayBuffer` it keeps, per transition, what the pixel-wise learner needs:

- **Hindsight relabelling** (§IV-D.3, Fig. 8). The buffer knows nothing about the env; the env opts
  in by adding, to the ``info`` of a step whose end state would be a goal under some other class
  assignment, an entry

      info["relabelled"] = {"obs": o_t*, "next_obs": o_{t+1}*, "reward": r*, "terminated": bool}

  with both observations already re-rendered under that assignment. The buffer stores that
  transition, with the executed action and the same next-state mask, right after the original.
  ``relabel="changed"`` (default) stores it only when the original step changed the observation:
  the twin of a no-op would teach that doing nothing in an almost-sorted state solves it.
  ``"all"`` is the paper's rule, ``"off"`` ignores the key.
- **Next-state action masks**, packed to bits (``n_actions / 8`` bytes per transition), so that the
  double-DQN argmax over s' considers only actions the env allowed there. Transitions stored
  without a mask get an all-True one (the paper's all-pixel argmax).
- **No-op transitions** — the observation did not change — are detected with `unchanged`.
  ``noop="keep"`` stores them as they are; ``"penalty"`` subtracts ``noop_penalty`` from their
  reward; ``"terminal"`` also marks them terminal, so their target is the reward alone.
- **Demonstrations**: `add_demonstration` writes into a second buffer that the ring never
  overwrites; `sample_arrays` draws a given share of each batch from it and flags those rows for
  the margin loss. A kept transition stored with ``expert=False`` (e.g. a teacher's counterfactual:
  an action it tried in a copy of the env and rejected) is drawn the same way but not flagged: it
  is trained with the TD loss only, as the margin loss would push its action up.

Storage is flat — one transition per slot whatever the number of envs — because a relabelled
transition belongs to one sub-env only. Pickling (``save_replay_buffer``) writes only the filled
part of the arrays (demonstrations included), so checkpoints of a young buffer stay small.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer

#: The info key of the hindsight protocol.
RELABEL_KEY = "relabelled"
#: The info key of the correction protocol (`sb3_pixeldqn.pixel_dqn`, ``PixelDoubleDQN``'s
#: "Corrections"): the env executed another action than the one it was given.
CORRECTION_KEY = "correction"
RELABEL_MODES = ("changed", "all", "off")
NOOP_MODES = ("keep", "penalty", "terminal")
_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts", "next_masks", "expert")


def unchanged(obs: np.ndarray, next_obs: np.ndarray) -> bool:
    """True when a step left the observation exactly as it was (a no-op as far as the agent can tell)."""
    return bool(np.array_equal(obs, next_obs))


class TransitionBatch(NamedTuple):
    """A sampled batch as numpy arrays (before any augmentation and before moving to torch)."""

    observations: np.ndarray  # (B, C, H, W) uint8
    actions: np.ndarray  # (B,) int64
    next_observations: np.ndarray  # (B, C, H, W) uint8
    rewards: np.ndarray  # (B,) float32
    dones: np.ndarray  # (B,) float32, timeouts already counted as not done
    next_masks: np.ndarray  # (B, n_actions) bool
    is_demo: np.ndarray  # (B,) bool


class HindsightRelabelReplayBuffer(ReplayBuffer):
    """Replay buffer of ``buffer_size`` transitions with relabelled twins, next-state masks,
    no-op handling and a kept demonstration store (see the module docstring).

    :param buffer_size: total number of transitions kept (over all envs, relabelled ones included).
    :param observation_space: the env's observation space.
    :param action_space: the env's ``Discrete`` action space.
    :param device: where sampled batches go.
    :param n_envs: number of parallel envs whose steps ``add`` receives.
    :param optimize_memory_usage: not supported (relabelled transitions break the obs/next_obs chain).
    :param handle_timeout_termination: time-limit truncations are stored as non-terminal.
    :param relabel: ``"changed"``, ``"all"`` or ``"off"``: which relabelled twins are stored.
    :param noop: ``"keep"``, ``"penalty"`` or ``"terminal"``: how unchanged-observation steps are stored.
    :param noop_penalty: subtracted from the reward of a no-op step unless ``noop="keep"``.
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
        relabel: str = "changed",
        noop: str = "keep",
        noop_penalty: float = 1.0,
    ) -> None:
        if optimize_memory_usage:
            raise ValueError(
                "HindsightRelabelReplayBuffer does not support optimize_memory_usage=True: "
                "relabelled transitions are not followed by their next observation"
            )
        if not isinstance(action_space, spaces.Discrete):
            raise ValueError(f"HindsightRelabelReplayBuffer needs a Discrete action space, got {action_space}")
        if relabel not in RELABEL_MODES:
            raise ValueError(f"relabel must be one of {RELABEL_MODES}, got {relabel!r}")
        if noop not in NOOP_MODES:
            raise ValueError(f"noop must be one of {NOOP_MODES}, got {noop!r}")
        super().__init__(
            buffer_size, observation_space, action_space, device, n_envs=1,
            optimize_memory_usage=False, handle_timeout_termination=handle_timeout_termination,
        )
        self.n_source_envs = n_envs
        self.n_actions = int(action_space.n)
        self.relabel = relabel
        self.noop = noop
        self.noop_penalty = float(noop_penalty)
        self.next_masks = np.zeros((self.buffer_size, (self.n_actions + 7) // 8), dtype=np.uint8)
        #: Per slot: the margin loss applies when the transition is drawn as a demonstration
        #: (meaningful in the demonstration store; `add_demonstration` sets it).
        self.expert = np.zeros(self.buffer_size, dtype=bool)
        self._expert = True
        self.n_relabelled = 0
        self.n_noop = 0
        #: Demonstration transitions, never overwritten by the ring (None until the first one).
        self.demonstrations: HindsightRelabelReplayBuffer | None = None

    # ------------------------------------------------------------------ adding
    def add(  # type: ignore[override]  # SB3's add plus the next masks; returns per-env no-op flags
        self,
        obs: np.ndarray,
        next_obs: np.ndarray,
        action: np.ndarray,
        reward: np.ndarray,
        done: np.ndarray,
        infos: list[dict[str, Any]],
        next_action_masks: np.ndarray | None = None,
    ) -> list[bool]:
        """Store each env's transition, then its relabelled twin if the env reported one.

        ``next_action_masks``: ``(n_envs, n_actions)`` bool, the actions allowed in each next state
        (None: all of them). Returns, per env, whether its step was a no-op (observation unchanged),
        so that callers can log what the buffer detected without comparing the observations again.
        """
        noops = []
        obs, next_obs = np.asarray(obs), np.asarray(next_obs)
        action, reward, done = np.asarray(action), np.asarray(reward, dtype=np.float32), np.asarray(done)
        for i, info in enumerate(infos):
            mask = None if next_action_masks is None else self._packed(next_action_masks[i])
            r, d = float(reward[i]), float(done[i])
            changed = not unchanged(obs[i], next_obs[i])
            noops.append(not changed)
            if not changed:
                self.n_noop += 1
                if self.noop != "keep":
                    r -= self.noop_penalty
                if self.noop == "terminal":
                    d = 1.0
                    info = {**info, "TimeLimit.truncated": False}
            self._add_one(obs[i], next_obs[i], action[i], r, d, info, mask)
            relabelled = info.get(RELABEL_KEY)
            if relabelled is not None and (self.relabel == "all" or (self.relabel == "changed" and changed)):
                self._add_relabelled(relabelled, action[i], mask)
        return noops

    def _add_one(self, obs: np.ndarray, next_obs: np.ndarray, action: Any, reward: float, done: float,
                 info: dict[str, Any], packed_mask: np.ndarray | None) -> None:
        self.next_masks[self.pos] = 255 if packed_mask is None else packed_mask
        self.expert[self.pos] = self._expert
        super().add(obs[None], next_obs[None], np.asarray(action).reshape(1, -1), np.array([reward]),
                    np.array([done]), [info])

    def _packed(self, mask: np.ndarray) -> np.ndarray:
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.shape != (self.n_actions,):
            raise ValueError(
                f"next-state action mask must be a bool array of shape ({self.n_actions},), "
                f"got dtype {mask.dtype} and shape {mask.shape}"
            )
        return np.packbits(mask)

    def _add_relabelled(self, relabelled: dict[str, Any], action: Any, packed_mask: np.ndarray | None) -> None:
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
        self._add_one(r_obs, r_next, action, r_reward, r_done, {}, packed_mask)
        self.n_relabelled += 1

    def add_demonstration(self, obs: np.ndarray, next_obs: np.ndarray, action: np.ndarray, reward: np.ndarray,
                          done: np.ndarray, infos: list[dict[str, Any]],
                          next_action_masks: np.ndarray | None = None, capacity: int = 10_000,
                          expert: bool = True) -> None:
        """Like `add`, into the demonstration store (created with ``capacity`` slots on first use).
        ``expert=False``: kept and drawn like the others, but not trained with the margin loss (an
        action the demonstrator did not choose, e.g. one it saw fail)."""
        if self.demonstrations is None:
            self.demonstrations = HindsightRelabelReplayBuffer(
                capacity, self.observation_space, self.action_space, self.device,
                handle_timeout_termination=self.handle_timeout_termination,
                relabel=self.relabel, noop=self.noop, noop_penalty=self.noop_penalty,
            )
        demos = self.demonstrations
        demos._expert = bool(expert)
        try:
            demos.add(obs, next_obs, action, reward, done, infos, next_action_masks)
        finally:
            demos._expert = True

    @property
    def n_stored(self) -> int:
        return self.buffer_size if self.full else self.pos

    # ------------------------------------------------------------------ sampling
    def sample_arrays(self, batch_size: int, demo_fraction: float = 0.0,
                      rng: np.random.Generator | None = None) -> TransitionBatch:
        """``batch_size`` transitions as numpy arrays: ``round(demo_fraction * batch_size)`` from the
        demonstrations (all of them while the ring is empty), the rest from the ring."""
        if not 0.0 <= demo_fraction <= 1.0:
            raise ValueError(f"demo_fraction must lie in [0, 1], got {demo_fraction}")
        rng = rng or np.random.default_rng(np.random.randint(2**31))
        demos = self.demonstrations
        n_demo = 0
        if demos is not None and demos.n_stored > 0:
            n_demo = batch_size if self.n_stored == 0 else int(round(demo_fraction * batch_size))
        own = self._arrays(rng.integers(0, self.n_stored, size=batch_size - n_demo)) if n_demo < batch_size else None
        if own is not None:  # the ring's rows are never demonstrations
            own = own._replace(is_demo=np.zeros(len(own.is_demo), dtype=bool))
        if n_demo == 0:
            assert own is not None
            return own
        demo = demos._arrays(rng.integers(0, demos.n_stored, size=n_demo))  # type: ignore[union-attr]
        if own is None:
            return demo
        return TransitionBatch(*(np.concatenate([a, b]) for a, b in zip(own, demo)))

    def _arrays(self, inds: np.ndarray) -> TransitionBatch:
        """The transitions at ``inds``; ``is_demo`` holds their expert flags (`sample_arrays` keeps
        them for rows of the demonstration store and clears them for the ring's)."""
        masks = np.unpackbits(self.next_masks[inds], axis=1, count=self.n_actions).astype(bool)
        dones = self.dones[inds, 0] * (1 - self.timeouts[inds, 0])
        return TransitionBatch(
            self.observations[inds, 0], self.actions[inds, 0, 0].astype(np.int64), self.next_observations[inds, 0],
            self.rewards[inds, 0].astype(np.float32), dones.astype(np.float32), masks, self.expert[inds],
        )

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        for name in _ARRAYS:
            state[name] = state[name][: self.n_stored]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        if "next_masks" not in state:  # a buffer pickled before masks were stored: all actions allowed
            n_actions = int(state["action_space"].n)
            state["next_masks"] = np.full((len(state["observations"]), (n_actions + 7) // 8), 255, dtype=np.uint8)
            state.setdefault("n_actions", n_actions)
        if "expert" not in state:  # pickled before counterfactuals: every kept transition was the demonstrator's
            state["expert"] = np.ones(len(state["observations"]), dtype=bool)
        for key, default in (("relabel", "all"), ("noop", "keep"), ("noop_penalty", 1.0),
                             ("n_noop", 0), ("demonstrations", None), ("_expert", True)):
            state.setdefault(key, default)
        for name in _ARRAYS:
            stored = state[name]
            full = np.zeros((state["buffer_size"], *stored.shape[1:]), dtype=stored.dtype)
            full[: len(stored)] = stored
            state[name] = full
        self.__dict__.update(state)
