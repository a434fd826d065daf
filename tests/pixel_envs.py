"""Tiny synthetic image envs with a known best pixel, for testing sb3_pixeldqn without physics, and a fixed-score
pixel policy for testing test-time wrappers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np


class FindTheSquareEnv(gym.Env):
    """A bright 3x3 square on a dark (C, H, W) image; acting on it solves the episode.

    Action ``a = m * H * W + row * W + col`` over ``n_maps`` maps; only map ``good_map`` counts.
    Reward 0 and terminated when the chosen pixel of ``good_map`` lies on the square, else -1;
    truncated after ``max_steps``. The optimal Q is 0 on the square of ``good_map`` and
    -1 - gamma * ... elsewhere, so the greedy policy is known exactly.
    """

    metadata = {"render_modes": []}

    def __init__(self, shape: tuple[int, int, int] = (4, 12, 20), n_maps: int = 1, good_map: int = 0,
                 max_steps: int = 5, relabel: bool = False, directional: bool = False) -> None:
        self.shape = shape
        self.n_maps = n_maps
        self.good_map = good_map
        self.max_steps = max_steps
        self.relabel = relabel
        # directional: a marker bar (channel 1 only) sits 3 cells left or right of the square and
        # the paying map is map 1 (0°) when it is left, map 2 (180°) when it is right — a task
        # that respects the 180° equivariance of rotated push maps.
        self.directional = directional
        self._marker_left = True
        self.observation_space = gym.spaces.Box(0, 255, shape, dtype=np.uint8)
        self.action_space = gym.spaces.Discrete(n_maps * shape[1] * shape[2])
        self.num_objects = 1
        self._centre = (0, 0)
        self._t = 0

    def set_num_objects(self, n: int) -> None:
        self.num_objects = int(n)

    def _obs(self) -> np.ndarray:
        obs = np.zeros(self.shape, dtype=np.uint8)
        r, c = self._centre
        obs[:, r - 1:r + 2, c - 1:c + 2] = 255
        if self.directional:
            mc = c - 3 if self._marker_left else c + 3
            obs[1, r - 1:r + 2, mc] = 255
        return obs

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        _, h, w = self.shape
        margin = 4 if self.directional else 1
        self._centre = (int(self.np_random.integers(1, h - 1)), int(self.np_random.integers(margin, w - margin)))
        self._marker_left = bool(self.np_random.integers(2))
        if self.directional:
            self.good_map = 1 if self._marker_left else 2
        self._t = 0
        return self._obs(), {"num_objects": self.num_objects}

    def on_square(self, action: int) -> bool:
        _, h, w = self.shape
        m, rest = divmod(int(action), h * w)
        row, col = divmod(rest, w)
        return m == self.good_map and abs(row - self._centre[0]) <= 1 and abs(col - self._centre[1]) <= 1

    def action_masks(self) -> np.ndarray:
        """sb3-contrib's convention: the square's pixels on every map (which map pays must be learned)."""
        return np.tile(self._obs()[0].reshape(-1) > 0, self.n_maps)

    def step(self, action):
        self._t += 1
        success = self.on_square(action)
        obs = self._obs()
        info = {"is_success": success, "num_objects": self.num_objects}
        if self.relabel and not success:
            # a stand-in for the hindsight protocol: pretend the relabelled state is solved
            info["relabelled"] = {"obs": obs // 2, "next_obs": obs // 3, "reward": 0.0, "terminated": True}
        return obs, (0.0 if success else -1.0), success, (not success and self._t >= self.max_steps), info


class CoinEnv(FindTheSquareEnv):
    """One-step episodes that succeed with probability ``p_success`` whatever the action.

    ``set_num_objects`` takes effect at the next reset, like ShelfSort-v0; ``info["num_objects"]``
    is the N the episode was drawn with, so a test can check when a curriculum change lands.
    """

    def __init__(self, p_success: float = 1.0, **kw) -> None:
        super().__init__(**kw)
        self.p_success = p_success
        self._pending = self.num_objects

    def set_num_objects(self, n: int) -> None:
        self._pending = int(n)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self.num_objects = self._pending
        return super().reset(seed=seed, options=options)

    def step(self, action):
        success = bool(self.np_random.random() < self.p_success)
        info = {"is_success": success, "num_objects": self.num_objects}
        return self._obs(), (0.0 if success else -1.0), True, False, info


class SquareSupervisor(gym.Wrapper):
    """Intervenes (sb3_pixeldqn's ``info["correction"]``) on every action off the square of the
    paying map: executes the square's centre on that map instead and reports the vetoed action as
    ending the episode with reward -10 and an all-zero next observation, as `shelf_env.privileged.lookahead.
    FallGuard` reports a vetoed pick. ``report`` replaces the report (to test bad ones)."""

    def __init__(self, env: FindTheSquareEnv, report=None) -> None:
        super().__init__(env)
        self.report = report
        self.corrections = 0

    def step(self, action):
        base = self.env.unwrapped
        action = int(action)
        executed = action
        if not base.on_square(action):
            _, h, w = base.shape
            executed = base.good_map * h * w + base._centre[0] * w + base._centre[1]
        vetoed_next = np.zeros(base.shape, dtype=np.uint8)
        obs, reward, terminated, truncated, info = self.env.step(executed)
        if executed != action:
            self.corrections += 1
            report = {"action": action, "executed": executed, "reward": -10.0, "next_obs": vetoed_next,
                      "terminated": True}
            info = {**info, "correction": report if self.report is None else self.report(report)}
        return obs, reward, terminated, truncated, info


class ScoresPolicy:
    """A greedy pixel policy over fixed scores that honours masks (as a PixelDoubleDQN does), acting on
    observations of ``obs_shape`` (C, H, W); ``scores`` holds one value per action (``n_maps * H * W``)."""

    def __init__(self, scores: np.ndarray, obs_shape: tuple[int, int, int]) -> None:
        self.scores = np.asarray(scores, float).reshape(-1)
        self.observation_space = gym.spaces.Box(0, 255, obs_shape, np.uint8)
        self.action_space = gym.spaces.Discrete(self.scores.size)

    def predict(self, obs, state=None, episode_start=None, deterministic=True, action_masks=None):
        masks = np.ones(self.scores.size, bool) if action_masks is None else np.asarray(action_masks, bool)
        return np.array(int(np.where(masks, self.scores, -np.inf).argmax())), state
