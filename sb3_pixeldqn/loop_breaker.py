"""`LoopBreaker`: a test-time guard that stops a greedy pixel policy from repeating itself.

A greedy policy is a function of the observation. Suppose an action leaves the observation
unchanged, or changes it so little that the same pixel stays best (a pick that lifts nothing, a
push against a wall). Then the policy chooses that action again and again until the episode runs
out of actions. These are the evaluation's ``loop`` failures (`shelf_env.evaluation.protocol.FAILURES`).
`LoopBreaker` wraps any policy whose ``predict`` takes sb3-contrib's ``action_masks`` (a
`PixelDoubleDQN`, a MaskablePPO, shelf_env's heuristics) and masks out the places it has already
acted at too often in the episode.

- It counts the actions executed per cell of each Q-map (pick, push-left, ...).
- A cell is *banned* for the rest of the episode once ``max_visits`` executed actions of its map lie
  within ``radius`` cells of it (Chebyshev distance).
- ``radius`` > 0 also catches the loops that drift by one pixel: (36, 59), (35, 59), (36, 58), ...
- Each call first asks the policy with the caller's masks. Where its choice is banned it asks
  again, among the allowed cells not banned, and the policy chooses its best remaining action
  (with a Q-map policy, the next-best pixel). Where no allowed cell is left unbanned, the first
  choice stands. A choice that is not banned is exactly the wrapped policy's, so its results
  differ from the bare policy's only where a ban redirects it.

Its memory is per episode. It is cleared where ``episode_start`` is True (SB3's ``predict``
convention; the shelf evaluation passes it at every reset) or by `reset`. It assumes that every
action it returns is executed, and the wrapped policy is memoryless (a DQN's ``state`` is None).

It reads nothing but its own actions: a robot can run it. It is not learned. It changes what the
policy does, so results with it are reported under their own policy name
(``"<policy>+loop-breaker"`` in `shelf_env.evaluation.protocol`).

With ``acts_masked`` False the wrapped policy gets no env masks from an evaluation. This holds for a
model trained with ``masked=False`` and for shelf_env's heuristics. It then gets the cells not
banned.
"""

from __future__ import annotations

import inspect
from typing import Any

import numpy as np
from gymnasium import spaces


def predict_takes(policy: Any, name: str) -> bool:
    """Whether ``policy.predict`` has a parameter ``name`` (e.g. ``"action_masks"``, ``"episode_start"``)."""
    try:
        return name in inspect.signature(policy.predict).parameters
    except (AttributeError, TypeError, ValueError):
        return False


class LoopBreaker:
    """Wrap ``policy`` (see the module docstring); ``predict`` has SB3's signature with ``action_masks``.

    :param policy: anything with ``predict(obs, state, episode_start, deterministic, action_masks)``,
        an ``action_space`` ``Discrete(n_maps * H * W)`` and an ``observation_space`` ``Box`` of
        shape ``(C, H, W)``.
    :param max_visits: executed actions of one map near a cell that ban it (>= 1).
    :param radius: the neighbourhood of a cell, in cells (>= 0; 0: the cell itself).
    """

    def __init__(self, policy: Any, max_visits: int = 3, radius: int = 1) -> None:
        if isinstance(max_visits, bool) or not isinstance(max_visits, (int, np.integer)) or max_visits < 1:
            raise ValueError(f"max_visits must be an integer >= 1, got {max_visits!r}")
        if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
            raise ValueError(f"radius must be an integer >= 0, got {radius!r}")
        action_space = getattr(policy, "action_space", None)
        obs_space = getattr(policy, "observation_space", None)
        if not isinstance(action_space, spaces.Discrete) or not isinstance(obs_space, spaces.Box) \
                or len(obs_space.shape) != 3:
            raise ValueError(f"LoopBreaker needs a pixel policy (a Discrete action space over Q-maps and a (C, H, W) "
                             f"Box observation space); {type(policy).__name__} has {action_space} and {obs_space}")
        height, width = int(obs_space.shape[1]), int(obs_space.shape[2])
        if int(action_space.n) % (height * width):
            raise ValueError(f"{type(policy).__name__}'s {action_space.n} actions are not whole {height}x{width} "
                             f"maps of its observation")
        if not predict_takes(policy, "action_masks"):
            raise ValueError(f"LoopBreaker steers a policy through action_masks; {type(policy).__name__}.predict "
                             "takes none")
        self.policy = policy
        self.max_visits = int(max_visits)
        self.radius = int(radius)
        self.action_space = action_space
        self.observation_space = obs_space
        self._layout = (int(action_space.n) // (height * width), height, width)
        self._visits: list[np.ndarray] = []
        #: ``bans``: cells newly banned; ``redirects``: choices a ban changed.
        self.stats = {"bans": 0, "redirects": 0}

    @property
    def acts_masked(self) -> bool:
        """Whether the wrapped policy acts with the env's masks (`shelf_env.evaluation.protocol.takes_action_masks`)."""
        return bool(getattr(self.policy, "acts_masked", True))

    def reset(self) -> None:
        """Forget every env's episode (as ``episode_start`` does for one env)."""
        self._visits = []

    def banned(self, env_index: int = 0) -> np.ndarray:
        """Bool ``(n_maps * H * W,)``: the actions banned in env ``env_index``'s episode so far."""
        if env_index >= len(self._visits):
            return np.zeros(int(self.action_space.n), dtype=bool)
        return self._banned(self._visits[env_index]).reshape(-1)

    def _banned(self, visits: np.ndarray) -> np.ndarray:
        r = self.radius
        padded = np.pad(visits, ((0, 0), (r, r), (r, r)))
        _, height, width = visits.shape
        near = np.zeros_like(visits)
        for dr in range(2 * r + 1):
            for dc in range(2 * r + 1):
                near += padded[:, dr:dr + height, dc:dc + width]
        return np.asarray(near >= self.max_visits)

    def predict(
        self,
        observation: np.ndarray,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """The wrapped policy's action among the allowed cells not banned (see the module docstring)."""
        obs = np.asarray(observation)
        single = obs.ndim == len(self.observation_space.shape)
        n_envs = 1 if single else len(obs)
        n_actions = int(self.action_space.n)
        if len(self._visits) != n_envs:
            self._visits = [np.zeros(self._layout, dtype=np.int32) for _ in range(n_envs)]
        if episode_start is not None:
            starts = np.asarray(episode_start, dtype=bool).reshape(-1)
            if starts.size != n_envs:
                raise ValueError(f"episode_start has {starts.size} entries for {n_envs} observation(s)")
            for k in np.flatnonzero(starts):
                self._visits[k][:] = 0
        if action_masks is None:
            masks = np.ones((n_envs, n_actions), dtype=bool)
        else:
            masks = np.asarray(action_masks, dtype=bool)
            if masks.size != n_envs * n_actions:
                raise ValueError(f"action_masks has {masks.size} entries; expected {n_envs} x {n_actions}")
            masks = masks.reshape(n_envs, n_actions)
        banned = np.stack([self._banned(v).reshape(-1) for v in self._visits])
        actions, new_state = self.policy.predict(obs, state=state, episode_start=episode_start,
                                                 deterministic=deterministic, action_masks=action_masks)
        flat = np.array(actions, copy=True).reshape(-1)
        allowed = masks & ~banned
        redirect = banned[np.arange(n_envs), flat] & allowed.any(axis=1)
        if redirect.any():  # ask again among the cells not banned; keep the answers of the redirected envs
            steered, new_state = self.policy.predict(obs, state=state, episode_start=episode_start,
                                                     deterministic=deterministic,
                                                     action_masks=allowed[0] if single else allowed)
            again = np.asarray(steered).reshape(-1)
            self.stats["redirects"] += int((redirect & (again != flat)).sum())
            flat[redirect] = again[redirect]
            actions = flat.reshape(np.shape(actions)).astype(np.asarray(actions).dtype)
        for i, action in enumerate(flat.tolist()):
            m, rest = divmod(action, self._layout[1] * self._layout[2])
            self._visits[i][m, rest // self._layout[2], rest % self._layout[2]] += 1
            self.stats["bans"] += int(self._banned(self._visits[i]).sum()) - int(banned[i].sum())
        return actions, new_state
