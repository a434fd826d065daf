"""`PixelDoubleDQN`: double deep Q-learning on pixel-wise Q-maps (§IV-D of the paper).

Per gradient step, on a batch of transitions (s, a, r, s', done):

- double-DQN target (the equation under Eq. 3): the online net picks the best action over all
  maps and pixels of s', the target net values that action, ``y = r + (1 - done) * gamma * Q'``;
  time-limit truncations are stored as not done, so they bootstrap;
- loss (Eq. 3): Huber on ``Q(s, a) - y`` at the executed pixel of the executed map only, so every
  other pixel and every other network gets exactly zero gradient;
- Polyak averaging of the target net after every gradient step, ``θ' <- (1 - β) θ' + β θ``.

Only what each term needs is computed: the online net on s for the executed map (with
gradients), the online net on s' for all maps (argmax, no gradients), and the target net on s'
for the selected map (no gradients).

Exploration is ε-greedy with ε annealed linearly from ``exploration_initial_eps`` to
``exploration_final_eps`` over ``exploration_timesteps`` steps of the current *stage*;
`restart_exploration` starts a new stage (the curriculum calls it when N grows). With
``exploration_mask="<method>"`` an exploratory action is a map drawn uniformly among the maps
with a useful pixel, then a pixel drawn uniformly among that map's useful pixels: the algorithm
calls ``env.env_method("<method>")``, which must return a boolean array with one entry per action
(an all-False mask falls back to uniform over all actions).
"""

from __future__ import annotations

import os
import pathlib
import pickle
import zipfile
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import polyak_update

from sb3_pixeldqn.buffers import HindsightRelabelReplayBuffer
from sb3_pixeldqn.policies import FCNPolicy, PixelQNetwork, describe_layout

SelfPixelDoubleDQN = TypeVar("SelfPixelDoubleDQN", bound="PixelDoubleDQN")

# Defaults of the paper (§IV-D.2, §IV-D.3).
LEARNING_RATE = 1e-4
BATCH_SIZE = 32
GAMMA = 0.9
POLYAK_BETA = 1e-3
EXPLORATION_INITIAL_EPS = 0.8
EXPLORATION_FINAL_EPS = 0.01
# Not given by the paper; sized for CPU budgets (a few thousand steps per curriculum stage).
EXPLORATION_TIMESTEPS = 2_000
BUFFER_SIZE = 50_000


class PixelDoubleDQN(OffPolicyAlgorithm):
    """Double DQN with a single-pixel Huber loss over the Q-maps of an `FCNPolicy`.

    :param policy: ``"FCNPolicy"`` or a subclass of it.
    :param env: an env with a ``Box(0, 255, (C, H, W), uint8)`` observation and a
        ``Discrete(n_maps * H * W)`` action space.
    :param learning_rate: Adam learning rate (paper: 1e-4); weight decay is in ``policy_kwargs``
        (``optimizer_kwargs``, default 2e-5).
    :param buffer_size: replay buffer capacity in transitions.
    :param learning_starts: steps of uniform (or masked) random actions before learning starts.
    :param batch_size: transitions per gradient step (paper: 32).
    :param tau: Polyak rate β of the target update after each gradient step (paper: 1e-3).
    :param gamma: discount (paper: 0.9).
    :param train_freq: env steps between training phases.
    :param gradient_steps: gradient steps per training phase.
    :param replay_buffer_class: defaults to `HindsightRelabelReplayBuffer`.
    :param replay_buffer_kwargs: extra keyword arguments of the replay buffer.
    :param exploration_initial_eps: ε at the start of each stage (paper: 0.8).
    :param exploration_final_eps: ε at the end of the annealing (paper: 0.01).
    :param exploration_timesteps: env steps over which ε is annealed within a stage.
    :param exploration_mask: name of an env method returning a boolean mask over actions to draw
        exploratory actions from (None: uniform over all actions).
    :param max_grad_norm: gradient-norm clip (None: no clipping, as in the paper).
    :param stats_window_size: episodes averaged for the rollout logs.
    :param tensorboard_log: TensorBoard log folder (None: no TensorBoard).
    :param policy_kwargs: keyword arguments of the policy (``maps``, ``widths``, ...).
    :param verbose: 0 silent, 1 info, 2 debug.
    :param seed: random seed.
    :param device: ``"auto"`` uses a GPU when there is one.
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {"FCNPolicy": FCNPolicy}
    policy: FCNPolicy
    q_net: PixelQNetwork
    q_net_target: PixelQNetwork

    def __init__(
        self,
        policy: str | type[FCNPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = LEARNING_RATE,
        buffer_size: int = BUFFER_SIZE,
        learning_starts: int = 100,
        batch_size: int = BATCH_SIZE,
        tau: float = POLYAK_BETA,
        gamma: float = GAMMA,
        train_freq: int | tuple[int, str] = 1,
        gradient_steps: int = 1,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        exploration_initial_eps: float = EXPLORATION_INITIAL_EPS,
        exploration_final_eps: float = EXPLORATION_FINAL_EPS,
        exploration_timesteps: int = EXPLORATION_TIMESTEPS,
        exploration_mask: str | None = None,
        max_grad_norm: float | None = None,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        _init_setup_model: bool = True,
    ) -> None:
        super().__init__(
            policy,
            env,
            learning_rate,
            buffer_size,
            learning_starts,
            batch_size,
            tau,
            gamma,
            train_freq,
            gradient_steps,
            action_noise=None,
            replay_buffer_class=replay_buffer_class or HindsightRelabelReplayBuffer,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=False,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            seed=seed,
            sde_support=False,
            supported_action_spaces=(spaces.Discrete,),
            support_multi_env=True,
        )
        if not 0.0 <= exploration_final_eps <= 1.0 or not 0.0 <= exploration_initial_eps <= 1.0:
            raise ValueError("exploration_initial_eps and exploration_final_eps must lie in [0, 1]")
        if exploration_timesteps < 1:
            raise ValueError(f"exploration_timesteps must be >= 1, got {exploration_timesteps}")
        self.exploration_initial_eps = exploration_initial_eps
        self.exploration_final_eps = exploration_final_eps
        self.exploration_timesteps = int(exploration_timesteps)
        self.exploration_mask = exploration_mask
        self.max_grad_norm = max_grad_norm
        #: Env steps since the current exploration stage began (saved with the model).
        self.stage_timesteps = 0
        self.exploration_rate = exploration_initial_eps
        #: Written by `CurriculumCallback` so that training resumes at its stage after load.
        self.curriculum_state: dict[str, Any] | None = None
        if _init_setup_model:
            self._setup_model()

    # ------------------------------------------------------------------ setup
    def _setup_model(self) -> None:
        super()._setup_model()
        self.q_net = self.policy.q_net
        self.q_net_target = self.policy.q_net_target
        self.exploration_rate = self._epsilon(self.stage_timesteps)

    def _epsilon(self, stage_timesteps: int) -> float:
        progress = min(1.0, stage_timesteps / self.exploration_timesteps)
        return self.exploration_initial_eps + progress * (self.exploration_final_eps - self.exploration_initial_eps)

    def restart_exploration(self) -> None:
        """Start a new exploration stage: ε goes back to ``exploration_initial_eps`` and anneals again."""
        self.stage_timesteps = 0
        self.exploration_rate = self._epsilon(0)

    def _on_step(self) -> None:
        self.stage_timesteps += self.n_envs
        self.exploration_rate = self._epsilon(self.stage_timesteps)
        self.logger.record("rollout/exploration_rate", self.exploration_rate)

    # ------------------------------------------------------------------ maths
    def double_dqn_target(self, next_obs: th.Tensor, rewards: th.Tensor, dones: th.Tensor) -> th.Tensor:
        """y = r + (1 - done) γ Q'(s', argmax_a' Q(s', a'))  (the equation under Eq. 3).

        The online net chooses a' over all maps and pixels; the target net values a' on its map only.
        """
        with th.no_grad():
            next_images = self.policy.images(next_obs)
            best = self.policy.all_q_maps(self.q_net, next_images).flatten(1).argmax(dim=1)
            next_q = self.policy.q_values_at(self.q_net_target, next_images, best)
            return rewards.reshape(-1) + (1.0 - dones.reshape(-1)) * self.gamma * next_q

    def pixel_loss(self, obs: th.Tensor, actions: th.Tensor, targets: th.Tensor) -> th.Tensor:
        """Huber loss (Eq. 3) on the executed pixel of the executed map, mean over the batch."""
        q = self.policy.q_values_at(self.q_net, self.policy.images(obs), actions)
        return F.smooth_l1_loss(q, targets)

    def train(self, gradient_steps: int, batch_size: int = BATCH_SIZE) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses = []
        for _ in range(gradient_steps):
            batch = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            targets = self.double_dqn_target(batch.next_observations, batch.rewards, batch.dones)
            loss = self.pixel_loss(batch.observations, batch.actions, targets)
            self.policy.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if self.max_grad_norm is not None:
                th.nn.utils.clip_grad_norm_(self.q_net.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
            polyak_update(self.q_net.parameters(), self.q_net_target.parameters(), self.tau)
            losses.append(loss.item())
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", float(np.mean(losses)))

    # ------------------------------------------------------------- exploration
    def _sample_action(
        self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """ε-greedy per env; before ``learning_starts`` every action is exploratory."""
        if self.num_timesteps < learning_starts:
            explore = np.ones(n_envs, dtype=bool)
        else:
            explore = np.random.rand(n_envs) < self.exploration_rate
        actions = np.zeros(n_envs, dtype=np.int64)
        if not explore.all():
            greedy, _ = self.policy.predict(self._last_obs, deterministic=True)  # type: ignore[arg-type]
            actions[~explore] = np.asarray(greedy).reshape(-1)[~explore]
        if explore.any():
            actions[explore] = self._exploratory_actions(np.flatnonzero(explore))
        return actions, actions

    def _exploratory_actions(self, env_indices: np.ndarray) -> np.ndarray:
        n_actions = int(self.action_space.n)  # type: ignore[attr-defined]
        if self.exploration_mask is None:
            return np.random.randint(n_actions, size=len(env_indices))
        masks = self.env.env_method(self.exploration_mask, indices=[int(i) for i in env_indices])  # type: ignore[union-attr]
        actions = []
        for mask in masks:
            mask = np.asarray(mask, dtype=bool).reshape(-1)
            if mask.shape != (n_actions,):
                raise ValueError(
                    f"env method {self.exploration_mask!r} returned a mask of {mask.size} entries; "
                    f"expected one per action ({n_actions})"
                )
            actions.append(draw_masked_action(mask, self.policy.n_maps, np.random))
        return np.asarray(actions, dtype=np.int64)

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Greedy action (Eq. 1) if ``deterministic``, else ε-greedy with uniform exploration (as SB3's DQN)."""
        action, state = self.policy.predict(observation, state, episode_start, deterministic=True)
        if not deterministic:
            action = np.array(action, copy=True)
            flat = action.reshape(-1)
            explore = np.random.rand(flat.size) < self.exploration_rate
            flat[explore] = np.random.randint(int(self.action_space.n), size=int(explore.sum()))  # type: ignore[attr-defined]
        return action, state

    # ------------------------------------------------------------- save / load
    def learn(
        self: SelfPixelDoubleDQN,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 4,
        tb_log_name: str = "PixelDoubleDQN",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfPixelDoubleDQN:
        return super().learn(
            total_timesteps=total_timesteps,
            callback=callback,
            log_interval=log_interval,
            tb_log_name=tb_log_name,
            reset_num_timesteps=reset_num_timesteps,
            progress_bar=progress_bar,
        )

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "q_net", "q_net_target"]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "policy.optimizer"], []

    def save(self, path: str | pathlib.Path | Any, exclude: Any = None, include: Any = None) -> None:
        """Save to ``path`` (``.zip`` added if it has no suffix) atomically: a crash leaves the old file intact."""
        if not isinstance(path, (str, pathlib.Path)):
            return super().save(path, exclude=exclude, include=include)
        _write_atomically(
            _with_suffix(path, ".zip"), lambda tmp: super(PixelDoubleDQN, self).save(tmp, exclude, include)
        )

    def save_replay_buffer(self, path: str | pathlib.Path | Any) -> None:
        """Pickle the replay buffer (filled part only) to ``path`` (``.pkl`` added if no suffix), atomically."""
        if not isinstance(path, (str, pathlib.Path)):
            return super().save_replay_buffer(path)
        _write_atomically(_with_suffix(path, ".pkl"), lambda tmp: super(PixelDoubleDQN, self).save_replay_buffer(tmp))

    @classmethod
    def load(  # type: ignore[override]
        cls: type[SelfPixelDoubleDQN],
        path: str | pathlib.Path | Any,
        env: GymEnv | None = None,
        device: th.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> SelfPixelDoubleDQN:
        """SB3 load, with errors that name the problem for corrupt files and mismatched map layouts."""
        if isinstance(path, (str, pathlib.Path)) and not _with_suffix(path, ".zip").is_file():
            raise FileNotFoundError(f"no {cls.__name__} checkpoint at {path}")
        try:
            return super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
        except (zipfile.BadZipFile, EOFError, KeyError, AssertionError, pickle.UnpicklingError, RuntimeError) as err:
            raise ValueError(
                f"{path} is not a readable {cls.__name__} checkpoint: {type(err).__name__}: {err}"
            ) from err
        except ValueError as err:
            if "spaces do not match" not in str(err):
                raise ValueError(f"{path} is not a readable {cls.__name__} checkpoint: {err}") from err
            data, _, _ = load_from_zip_file(path, load_data=True, device="cpu")
            maps = (data or {}).get("policy_kwargs", {}).get("maps")
            raise ValueError(
                f"checkpoint {path} does not fit this env: {err}. The checkpoint's Q-map layout is "
                f"{describe_layout(tuple(maps)) if maps else 'the default P+S layout'} over the observation "
                f"{(data or {}).get('observation_space')}; the env has {env.observation_space if env else '?'} "
                f"and {env.action_space if env else '?'}."
            ) from err


def draw_masked_action(mask: np.ndarray, n_maps: int, rng: Any) -> int:
    """One exploratory action from a boolean action mask: a map drawn uniformly among the maps with
    a useful pixel, then one of its useful pixels, so a primitive with a large mask (pushes) does
    not crowd out one with a small mask (picks). Uniform over all actions if the mask is empty.
    ``rng`` is anything with ``choice`` (``np.random`` or a ``np.random.Generator``)."""
    per_map = np.asarray(mask, dtype=bool).reshape(n_maps, -1)
    maps = np.flatnonzero(per_map.any(axis=1))
    if maps.size == 0:
        return int(rng.choice(per_map.size))
    m = int(rng.choice(maps))
    return m * per_map.shape[1] + int(rng.choice(np.flatnonzero(per_map[m])))


def _with_suffix(path: str | pathlib.Path, suffix: str) -> pathlib.Path:
    path = pathlib.Path(path)
    return path if path.suffix else path.with_suffix(suffix)


def _write_atomically(final: pathlib.Path, write: Any) -> None:
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f".{final.name}.partial")
    try:
        write(tmp)
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()
