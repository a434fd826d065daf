"""`PixelDoubleDQN`: double deep Q-learning on pixel-wise Q-maps (§IV-D of the paper).

Per gradient step, on a batch of transitions (s, a, r, s', done, mask'):

- double-DQN target (the equation under Eq. 3): the online net picks the best action of s' among
  the actions its mask allows (all maps and pixels with ``masked=False``, the paper's argmax), the
  target net values that action, ``y = r + (1 - done) * gamma * Q'``; time-limit truncations are
  stored as not done, so they bootstrap;
- loss (Eq. 3): Huber on ``Q(s, a) - y`` at the executed pixel of the executed map only, so every
  other pixel and every other network gets exactly zero gradient; plus, on demonstration rows, the
  strict large-margin loss of SDQfD (mean hinge ``Q(s, a) + margin - Q(s, a_E)`` over every action
  within the margin of the demonstrated one, `margin_loss`);
- target update after every ``target_update_interval`` gradient steps, ``θ' <- (1 - τ) θ' + τ θ``
  (paper: τ = β = 1e-3 every step; ``tau=1`` with an interval is a hard copy).

**Action masks** follow sb3-contrib's MaskablePPO: an env that offers ``action_masks()`` (a bool
array of ``action_space.n``, True = allowed) gets every choice the algorithm makes restricted to
it — exploratory and greedy actions while collecting, the argmax over s' (the buffer stores each
next state's mask, packed to bits), and `predict` when given ``action_masks=``. An untrained pixel
can then never win an argmax. ``masked=False`` keeps the paper's all-pixel argmax.

**Demonstrations** (`collect_demonstrations`): any object with SB3's ``predict`` plays episodes in
the training env; its transitions go to a store the replay ring never overwrites, and
``demo_fraction`` of every batch is drawn from it with the margin loss.

**Corrections** (DAgger-style, while training, `store_corrections`): an env (or a wrapper around
it, e.g. a supervisor that tries each action in a simulator copy first) may execute another action
than the one it was given. It then says so in that step's info:

    info["correction"] = {"action": a_vetoed, "executed": a_taken, "reward": r_vetoed,
                            "next_obs": o_vetoed, "terminated": bool}

The step's transition is stored with the executed action (it is what produced the next state), and
both halves of the correction are kept in the demonstration store: the vetoed action with what it
would have led to (TD loss only, ``expert=False``; a non-terminal one with every next action
allowed) and the executed transition as a demonstration (margin loss). So the learner is corrected
in exactly the states its own policy reaches. ``n_corrections`` counts them
(``rollout/corrections`` in the logs).

**Augmentation** (``augment=``): callables ``(obs, action, next_obs, next_mask, rng) -> (obs,
action, next_obs, next_mask)`` applied to every sampled transition, each drawing its own element
of a symmetry group of the task. The algorithm knows nothing of what they mean; an env package
supplies them (`shelf_env.symmetry`).

**An actor process** (`sb3_pixeldqn.actor.ActorVecEnv` as the env): the env steps in a second
process that plays this model's ε-greedy masked policy with a copy of its weights, refreshed every
few gradient steps, while the learner trains; `collect_rollouts` consumes those transitions
instead of stepping the env itself, at the same replay ratio.

Exploration is ε-greedy with ε annealed linearly from ``exploration_initial_eps`` to
``exploration_final_eps`` over ``exploration_timesteps`` steps of the current *stage*;
`restart_exploration` starts a new stage (the curriculum calls it when N grows). A masked
exploratory action is a map drawn uniformly among the maps with an allowed pixel, then one of
its allowed pixels.
"""

from __future__ import annotations

import pathlib
import pickle
import zipfile
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, RolloutReturn, Schedule, TrainFreq
from stable_baselines3.common.utils import polyak_update, should_collect_more_steps
from stable_baselines3.common.vec_env import VecEnv

from sb3_pixeldqn.actor import ActingRules, ActorVecEnv
from sb3_pixeldqn.buffers import CORRECTION_KEY, HindsightRelabelReplayBuffer, TransitionBatch
from sb3_pixeldqn.exploration import draw_masked_action
from sb3_pixeldqn.files import write_atomically
from sb3_pixeldqn.policies import FCNPolicy, PixelQNetwork, check_action_masks, describe_layout, masked_argmax

SelfPixelDoubleDQN = TypeVar("SelfPixelDoubleDQN", bound="PixelDoubleDQN")
#: ``(obs, action, next_obs, next_mask, rng) -> (obs, action, next_obs, next_mask)``: one symmetry
#: of the task applied to one transition (numpy arrays, the action a Python int).
Transform = Callable[[np.ndarray, int, np.ndarray, np.ndarray, np.random.Generator],
                     tuple[np.ndarray, int, np.ndarray, np.ndarray]]

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
# Large-margin loss on demonstrations (SDQfD as in BulletArm / equivariant FCN-DQN).
MARGIN = 0.1
MARGIN_WEIGHT = 0.1
DEMO_FRACTION = 0.25
#: The info key an env may set at an episode's end with the mask of its final observation (the
#: VecEnv has already reset when the algorithm could ask for it).
FINAL_MASK_KEY = "action_mask"
#: Slots of the demonstration store when a correction creates it (`store_corrections`).
CORRECTION_CAPACITY = 20_000
#: Steps over which ``rollout/noop_rate`` is averaged.
NOOP_WINDOW = 200


def get_action_masks(env: GymEnv) -> np.ndarray:
    """The env's current action masks, as sb3-contrib's ``get_action_masks``: ``(n_envs, n)`` for a
    VecEnv, ``(n,)`` for a Gymnasium env (through its wrappers)."""
    if isinstance(env, VecEnv):
        return np.stack(env.env_method("action_masks"))
    return np.asarray(env.get_wrapper_attr("action_masks")())


class PixelDoubleDQN(OffPolicyAlgorithm):
    """Double DQN with a single-pixel Huber loss over the Q-maps of an `FCNPolicy` (see the module docstring).

    :param policy: ``"FCNPolicy"`` or a subclass of it.
    :param env: an env with a ``Box(0, 255, (C, H, W), uint8)`` observation and a
        ``Discrete(n_maps * H * W)`` action space, optionally with ``action_masks()``.
    :param learning_rate: Adam learning rate (paper: 1e-4); weight decay is in ``policy_kwargs``
        (``optimizer_kwargs``, default 2e-5).
    :param buffer_size: replay buffer capacity in transitions.
    :param learning_starts: steps of random (or masked random) actions before learning starts.
    :param batch_size: transitions per gradient step (paper: 32).
    :param tau: target update rate: Polyak β (paper: 1e-3), or 1 for hard copies.
    :param gamma: discount (paper: 0.9).
    :param train_freq: env steps between training phases.
    :param gradient_steps: gradient steps per training phase.
    :param target_update_interval: gradient steps between target updates (paper: 1).
    :param replay_buffer_class: defaults to `HindsightRelabelReplayBuffer` (``relabel=``, ``noop=``
        in ``replay_buffer_kwargs``).
    :param replay_buffer_kwargs: extra keyword arguments of the replay buffer.
    :param exploration_initial_eps: ε at the start of each stage (paper: 0.8).
    :param exploration_final_eps: ε at the end of the annealing (paper: 0.01).
    :param exploration_timesteps: env steps over which ε is annealed within a stage.
    :param masked: restrict greedy collection and the argmax over s' to the env's ``action_masks()``.
        None (default): if the env offers them; False: the paper's all-pixel argmax; True: require them.
    :param masked_exploration: draw exploratory actions from the env's masks. None: same as ``masked``.
    :param demo_fraction: share of each batch drawn from demonstrations, once there are any.
    :param margin: the large-margin loss's margin between a demonstrated action and any other.
    :param margin_weight: weight of the large-margin loss (0 disables it).
    :param augment: symmetry transforms applied to every sampled transition (see `Transform`).
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
    observation_space: spaces.Box
    action_space: spaces.Discrete
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
        target_update_interval: int = 1,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        exploration_initial_eps: float = EXPLORATION_INITIAL_EPS,
        exploration_final_eps: float = EXPLORATION_FINAL_EPS,
        exploration_timesteps: int = EXPLORATION_TIMESTEPS,
        masked: bool | None = None,
        masked_exploration: bool | None = None,
        demo_fraction: float = DEMO_FRACTION,
        margin: float = MARGIN,
        margin_weight: float = MARGIN_WEIGHT,
        augment: Sequence[Transform] | None = None,
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
        if target_update_interval < 1:
            raise ValueError(f"target_update_interval must be >= 1, got {target_update_interval}")
        if not 0.0 <= demo_fraction <= 1.0:
            raise ValueError(f"demo_fraction must lie in [0, 1], got {demo_fraction}")
        if margin < 0 or margin_weight < 0:
            raise ValueError(f"margin and margin_weight must be >= 0, got {margin} and {margin_weight}")
        augment = list(augment or [])
        for transform in augment:
            if not callable(transform):
                raise ValueError(
                    f"augment must hold callables (obs, action, next_obs, next_mask, rng); got {transform!r}"
                )
        self.exploration_initial_eps = exploration_initial_eps
        self.exploration_final_eps = exploration_final_eps
        self.exploration_timesteps = int(exploration_timesteps)
        self.target_update_interval = int(target_update_interval)
        self.masked = masked
        self.masked_exploration = masked_exploration
        self.demo_fraction = float(demo_fraction)
        self.margin = float(margin)
        self.margin_weight = float(margin_weight)
        self.augment = augment
        self.max_grad_norm = max_grad_norm
        #: Env steps since the current exploration stage began (saved with the model).
        self.stage_timesteps = 0
        #: Env steps played by demonstration policies (not counted in ``num_timesteps``).
        self.demo_timesteps = 0
        self.exploration_rate = exploration_initial_eps
        #: Written by `CurriculumCallback` so that training resumes at its stage after load.
        self.curriculum_state: dict[str, Any] | None = None
        self._noop_history: deque[bool] = deque(maxlen=NOOP_WINDOW)
        #: Env steps whose action the env replaced (`store_corrections`; saved with the model).
        self.n_corrections = 0
        if _init_setup_model:
            self._setup_model()

    # ------------------------------------------------------------------ setup
    def _setup_model(self) -> None:
        super()._setup_model()
        self.q_net = self.policy.q_net
        self.q_net_target = self.policy.q_net_target
        self.exploration_rate = self._epsilon(self.stage_timesteps)
        if self.replay_buffer_class is None or not issubclass(self.replay_buffer_class, HindsightRelabelReplayBuffer):
            raise ValueError(
                f"PixelDoubleDQN needs a HindsightRelabelReplayBuffer (or a subclass), got {self.replay_buffer_class}"
            )
        self._sample_rng = np.random.default_rng(self.seed)
        self._resolve_masks()

    def set_env(self, env: GymEnv, force_reset: bool = True) -> None:
        """SB3's ``set_env``, also with another number of envs than the model had (SB3 refuses that):
        the replay buffer stores each env's transitions one by one and nothing else in the model
        depends on the number, so a run can move between one env and many (parallel envs on a
        machine with many cores). Spaces are checked as SB3 checks them."""
        env = self._wrap_env(env, self.verbose)
        self.n_envs = env.num_envs
        if isinstance(self.replay_buffer, HindsightRelabelReplayBuffer):
            self.replay_buffer.n_source_envs = env.num_envs
        super().set_env(env, force_reset)
        self._resolve_masks()

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
        if self._noop_history:
            self.logger.record("rollout/noop_rate", float(np.mean(self._noop_history)))

    # ------------------------------------------------------------------ masks
    @property
    def acts_masked(self) -> bool:
        """Whether this model acts within ``action_masks`` when they are available: False only for a
        model trained with ``masked=False`` (the paper's all-pixel argmax, kept at evaluation too)."""
        return self.masked is not False

    def _resolve_masks(self) -> None:
        """Decide once per env whether greedy collection / the target (``_use_masks``) and exploration
        (``_explore_masked``) use the env's masks; a clear error if they are required and missing."""
        has_masks = self.env is not None and bool(self.env.has_attr("action_masks"))
        if self.env is not None and not has_masks:
            if self.masked:
                raise ValueError("masked=True but the env has no action_masks() method; pass masked=False")
            if self.masked_exploration:
                raise ValueError("masked_exploration=True but the env has no action_masks() method")
        self._use_masks = has_masks if self.masked is None else bool(self.masked)
        explore = self.masked_exploration
        self._explore_masked = self._use_masks if explore is None else bool(explore)
        #: Masks of the training envs after the last step, valid while ``_last_obs`` is that step's
        #: observation (anything that resets the envs replaces ``_last_obs``).
        self._step_masks: tuple[Any, np.ndarray] | None = None

    def _current_masks(self) -> np.ndarray:
        """``(n_envs, n_actions)`` bool masks of the training envs now, checked."""
        assert self.env is not None
        return check_action_masks(get_action_masks(self.env), int(self.action_space.n), self.env.num_envs)

    # ------------------------------------------------------------------ maths
    def double_dqn_target(self, next_obs: th.Tensor, rewards: th.Tensor, dones: th.Tensor,
                          next_masks: th.Tensor | None = None) -> th.Tensor:
        """y = r + (1 - done) γ Q'(s', argmax_{a' allowed} Q(s', a'))  (the equation under Eq. 3).

        The online net chooses a' over the maps and pixels ``next_masks`` allows (all if None); the
        target net values a' on its map only.
        """
        with th.no_grad():
            next_images = self.policy.images(next_obs)
            q_next = self.policy.all_q_maps(self.q_net, next_images).flatten(1)
            best = masked_argmax(q_next, next_masks)
            next_q = self.policy.q_values_at(self.q_net_target, next_images, best)
            return rewards.reshape(-1) + (1.0 - dones.reshape(-1)) * self.gamma * next_q

    def pixel_loss(self, obs: th.Tensor, actions: th.Tensor, targets: th.Tensor,
                   demo_rows: th.Tensor | None = None) -> tuple[th.Tensor, th.Tensor | None]:
        """The training loss of one batch: (total, margin part or None).

        Huber loss (Eq. 3) on the executed pixel of the executed map, mean over the batch, plus
        ``margin_weight`` times the large-margin loss (`margin_loss`) of the rows in ``demo_rows``
        (bool, demonstration transitions), whose full Q-maps are computed for it.
        """
        if demo_rows is None or self.margin_weight <= 0:
            demo_rows = th.zeros(obs.shape[0], dtype=th.bool, device=obs.device)
        q, q_demo = self.policy.q_for_loss(self.policy.images(obs), actions, demo_rows)
        loss = F.smooth_l1_loss(q, targets)
        if not demo_rows.any():
            return loss, None
        margin = self.margin_loss(q_demo, actions[demo_rows])
        return loss + self.margin_weight * margin, margin

    def margin_loss(self, q_all: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """Strict large-margin loss of demonstrations (SDQfD), mean over rows ``(B, n_actions)``.

        Every action whose value comes within ``margin`` of the demonstrated action's is a violator;
        a row's loss is the mean over its violators of ``Q(s, a) + margin - Q(s, a_E)`` (0 without
        violators). DQfD's ``max_a [Q(s, a) + margin * (a != a_E)] - Q(s, a_E)`` penalises only the
        one largest action: on a map of thousands of pixels a flat Q-map is then a trap (the loss
        sits at the margin and its gradient reaches one pixel at a time) — measured in
        docs/experiments/learning-recipe.md, where the pick map of three runs went flat with it.
        """
        actions = actions.long().reshape(-1, 1)
        q_demo = q_all.gather(1, actions)
        excess = q_all + self.margin - q_demo  # > 0: within the margin of (or above) the demonstration
        others = th.ones_like(q_all, dtype=th.bool).scatter_(1, actions, False)
        violators = (excess > 0) & others
        per_row = (excess * violators).sum(dim=1) / violators.sum(dim=1).clamp(min=1)
        return per_row.mean()

    def augmented(self, batch: TransitionBatch) -> TransitionBatch:
        """Apply every transform of ``augment`` to every transition of ``batch``, checking what they return."""
        if not self.augment:
            return batch
        obs, actions, next_obs, masks = (batch.observations.copy(), batch.actions.copy(),
                                         batch.next_observations.copy(), batch.next_masks.copy())
        n_actions = int(self.action_space.n)
        for i in range(len(actions)):
            o, a, no, m = obs[i], int(actions[i]), next_obs[i], masks[i]
            for transform in self.augment:
                o, a, no, m = transform(o, a, no, m, self._sample_rng)
                if (np.shape(o) != obs.shape[1:] or np.shape(no) != obs.shape[1:] or np.shape(m) != masks.shape[1:]
                        or np.asarray(o).dtype != obs.dtype or np.asarray(m).dtype != np.bool_
                        or not 0 <= int(a) < n_actions):
                    raise ValueError(
                        f"augmentation {transform!r} changed a transition's layout: obs {np.shape(o)} "
                        f"{np.asarray(o).dtype}, next_obs {np.shape(no)}, mask {np.shape(m)} {np.asarray(m).dtype}, "
                        f"action {a}; expected obs {obs.shape[1:]} {obs.dtype}, mask {masks.shape[1:]} bool "
                        f"and an action in [0, {n_actions})"
                    )
            obs[i], actions[i], next_obs[i], masks[i] = o, a, no, m
        return batch._replace(observations=obs, actions=actions, next_observations=next_obs, next_masks=masks)

    def train(self, gradient_steps: int, batch_size: int = BATCH_SIZE) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses, margin_losses = [], []
        use_masks = self.acts_masked
        buffer = self.replay_buffer
        assert isinstance(buffer, HindsightRelabelReplayBuffer)  # _setup_model checks the class
        for _ in range(gradient_steps):
            batch = self.augmented(buffer.sample_arrays(batch_size, self.demo_fraction, self._sample_rng))
            obs = th.as_tensor(batch.observations, device=self.device)
            actions = th.as_tensor(batch.actions, device=self.device)
            masks = th.as_tensor(batch.next_masks, device=self.device) if use_masks else None
            targets = self.double_dqn_target(th.as_tensor(batch.next_observations, device=self.device),
                                             th.as_tensor(batch.rewards, device=self.device),
                                             th.as_tensor(batch.dones, device=self.device), masks)
            loss, margin = self.pixel_loss(obs, actions, targets, th.as_tensor(batch.is_demo, device=self.device))
            if margin is not None:
                margin_losses.append(margin.item())
            self.policy.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if self.max_grad_norm is not None:
                th.nn.utils.clip_grad_norm_(self.q_net.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
            self._n_updates += 1
            if self._n_updates % self.target_update_interval == 0:
                polyak_update(self.q_net.parameters(), self.q_net_target.parameters(), self.tau)
            losses.append(loss.item())
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", float(np.mean(losses)))
        if margin_losses:
            self.logger.record("train/margin_loss", float(np.mean(margin_losses)))

    # ------------------------------------------------------------- collection
    def collect_rollouts(
        self,
        env: VecEnv,
        callback: BaseCallback,
        train_freq: TrainFreq,
        replay_buffer: ReplayBuffer,
        action_noise: ActionNoise | None = None,
        learning_starts: int = 0,
        log_interval: int | None = None,
    ) -> RolloutReturn:
        """SB3's collection; with an `ActorVecEnv` as the env, the transitions its actor process
        played (`sb3_pixeldqn.actor`), consumed in order and handled exactly as SB3's loop handles
        the steps it takes itself: the callbacks' ``on_step`` (with ``actions``, ``new_obs``,
        ``rewards``, ``dones``, ``infos`` in their locals), the buffer, ε, the episode logs."""
        if not isinstance(env, ActorVecEnv):
            return super().collect_rollouts(env, callback, train_freq, replay_buffer, action_noise, learning_starts,
                                            log_interval)
        self.policy.set_training_mode(False)
        assert isinstance(replay_buffer, HindsightRelabelReplayBuffer)  # _setup_model checks the class
        num_collected_steps, num_collected_episodes = 0, 0
        callback.on_rollout_start()
        while should_collect_more_steps(train_freq, num_collected_steps, num_collected_episodes):
            self.update_actor(env)
            env.act()
            transition = env.receive()
            actions, new_obs, rewards, dones, infos = (transition.action, transition.new_obs, transition.reward,
                                                       transition.done, [transition.info])
            self._last_obs = transition.obs  # the observation the action was chosen in, as SB3 has it here
            self.num_timesteps += env.num_envs
            num_collected_steps += 1
            callback.update_locals(locals())
            if not callback.on_step():
                return RolloutReturn(num_collected_steps, num_collected_episodes, continue_training=False)
            self._update_info_buffer(infos, dones)
            next_obs = self._final_observations(new_obs, dones, infos)
            next_masks = transition.next_mask if self._use_masks else None
            stored = self.store_corrections(transition.obs, actions, next_obs, rewards, dones, infos, next_masks)
            noops = replay_buffer.add(transition.obs, next_obs, stored, rewards, dones, infos,
                                      next_action_masks=next_masks)
            self._noop_history.extend(noops)
            self._last_obs = self._last_original_obs = new_obs
            self._update_current_progress_remaining(self.num_timesteps, self._total_timesteps)
            self._on_step()
            if dones[0]:
                num_collected_episodes += 1
                self._episode_num += 1
                if log_interval is not None and self._episode_num % log_interval == 0:
                    self.dump_logs()
        callback.on_rollout_end()
        return RolloutReturn(num_collected_steps, num_collected_episodes, continue_training=True)  # one env

    def update_actor(self, env: ActorVecEnv) -> None:
        """Send ``env``'s actor this model's policy and acting rules (ε, warm-up, masks) when due."""
        rules = ActingRules(epsilon=float(self.exploration_rate), explore_all=self.num_timesteps < self.learning_starts,
                            masked=bool(self._use_masks), masked_exploration=bool(self._explore_masked),
                            n_maps=int(self.policy.n_maps))
        env.update(self.policy, self._n_updates, rules, self.seed)

    def _sample_action(
        self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """ε-greedy per env; before ``learning_starts`` every action is exploratory. Both kinds are
        drawn among the env's allowed actions when masks are in use."""
        if self.num_timesteps < learning_starts:
            explore = np.ones(n_envs, dtype=bool)
        else:
            explore = np.random.rand(n_envs) < self.exploration_rate
        masks = None
        if self._use_masks or self._explore_masked:
            cached = self._step_masks
            masks = cached[1] if cached is not None and cached[0] is self._last_obs else self._current_masks()
        actions = np.zeros(n_envs, dtype=np.int64)
        if not explore.all():
            greedy, _ = self.policy.predict(self._last_obs, deterministic=True,  # type: ignore[arg-type]
                                            action_masks=masks if self._use_masks else None)
            actions[~explore] = np.asarray(greedy).reshape(-1)[~explore]
        if explore.any():
            actions[explore] = self._exploratory_actions(explore, masks if self._explore_masked else None)
        return actions, actions

    def _exploratory_actions(self, explore: np.ndarray, masks: np.ndarray | None) -> np.ndarray:
        n_actions = int(self.action_space.n)
        if masks is None:
            return np.random.randint(n_actions, size=int(explore.sum()))
        return np.array([draw_masked_action(masks[i], self.policy.n_maps, np.random) for i in np.flatnonzero(explore)],
                        dtype=np.int64)

    def _next_masks(self, new_obs: Any, dones: np.ndarray, infos: list[dict[str, Any]]) -> np.ndarray | None:
        """Masks of the states each env's step reached (for the buffer), or None when unused.

        One query of the envs serves twice: the masks of ``new_obs`` are also those of the next
        action (cached in ``_step_masks``). For an env whose episode ended, the VecEnv has already
        reset, so its final mask is read from ``info["action_mask"]`` when the env provides it, else
        every action counts as allowed (that matters only for time-limit truncations: terminal
        transitions bootstrap nothing).
        """
        if not (self._use_masks or self._explore_masked):
            return None
        current = self._current_masks()
        self._step_masks = (new_obs, current)
        if not self._use_masks:
            return None
        masks = current.copy()
        for i, done in enumerate(dones):
            if done:
                final = infos[i].get(FINAL_MASK_KEY)
                masks[i] = True if final is None else check_action_masks(final, masks.shape[1], 1)[0]
        return masks

    @staticmethod
    def _final_observations(new_obs: Any, dones: np.ndarray, infos: list[dict[str, Any]]) -> np.ndarray:
        """The observations each env's step reached: ``new_obs`` with the final observation of
        auto-reset envs put back (a VecEnv returns the next episode's first one)."""
        next_obs = np.array(new_obs, copy=True)
        for i, done in enumerate(dones):
            if done and infos[i].get("terminal_observation") is not None:
                next_obs[i] = infos[i]["terminal_observation"]
        return next_obs

    def _store_transition(
        self,
        replay_buffer: ReplayBuffer,
        buffer_action: np.ndarray,
        new_obs: np.ndarray | dict[str, np.ndarray],
        reward: np.ndarray,
        dones: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        """SB3's store (terminal observations of auto-reset envs put back), plus the next-state masks."""
        next_obs = self._final_observations(new_obs, dones, infos)
        masks = self._next_masks(new_obs, dones, infos)
        assert isinstance(replay_buffer, HindsightRelabelReplayBuffer)  # _setup_model checks the class
        obs = np.asarray(self._last_obs)
        buffer_action = self.store_corrections(obs, buffer_action, next_obs, reward, dones, infos, masks)
        noops = replay_buffer.add(obs, next_obs, buffer_action, reward, dones, infos, next_action_masks=masks)
        self._noop_history.extend(noops)
        self._last_obs = new_obs
        self._last_original_obs = new_obs

    def store_corrections(self, obs: np.ndarray, actions: np.ndarray, next_obs: np.ndarray, rewards: np.ndarray,
                          dones: np.ndarray, infos: list[dict[str, Any]],
                          next_masks: np.ndarray | None) -> np.ndarray:
        """The actions to store for one step of the envs (``obs``: the states acted in, ``next_obs``:
        the states reached, final observations put back): ``actions`` with each env's executed action
        where its info reports a correction (see the module docstring). Each correction's
        vetoed action (TD loss only) and executed transition (a demonstration) go to the
        demonstration store, created with `CORRECTION_CAPACITY` slots if there is none yet."""
        actions = np.array(actions, dtype=np.int64, copy=True).reshape(-1)
        buffer = self.replay_buffer
        assert isinstance(buffer, HindsightRelabelReplayBuffer)  # _setup_model checks the class
        for i, info in enumerate(infos):
            report = info.get(CORRECTION_KEY)
            if report is None:
                continue
            vetoed, executed, reward, vetoed_next, terminated = self._check_correction(report)
            obs_i = np.asarray(obs[i])[None]
            self._keep_rejected(obs_i, vetoed, reward, vetoed_next, terminated, CORRECTION_CAPACITY)
            mask_i = None if next_masks is None else np.asarray(next_masks)[i:i + 1]
            buffer.add_demonstration(obs_i, np.asarray(next_obs[i])[None], np.array([executed]),
                                     np.asarray(rewards, dtype=np.float32).reshape(-1)[i:i + 1],
                                     np.asarray(dones).reshape(-1)[i:i + 1], [info], mask_i,
                                     capacity=CORRECTION_CAPACITY)
            actions[i] = executed
            self.n_corrections += 1
        if hasattr(self, "_logger"):  # set up by learn
            self.logger.record("rollout/corrections", self.n_corrections)
        return actions

    def _check_correction(self, report: Any) -> tuple[int, int, float, np.ndarray, bool]:
        """``info["correction"]``'s fields, or a clear error naming what does not fit the model."""
        n_actions = int(self.action_space.n)
        keys = ("action", "executed", "reward", "next_obs", "terminated")
        if not isinstance(report, dict) or not set(keys) <= set(report):
            raise ValueError(f'info["{CORRECTION_KEY}"] must be a dict with keys {list(keys)}, got {report!r:.200}')
        actions = (report["action"], report["executed"])
        next_obs = np.asarray(report["next_obs"])
        if not self._fits_layout(actions, next_obs):
            raise ValueError(f'info["{CORRECTION_KEY}"] reports actions {actions} and a next_obs of shape '
                             f"{next_obs.shape}; expected actions in [0, {n_actions}) and shape "
                             f"{self.observation_space.shape}")
        return int(actions[0]), int(actions[1]), float(report["reward"]), next_obs, bool(report["terminated"])

    def collect_demonstrations(self, demo_policy: Any, n_steps: int, capacity: int | None = None,
                               progress: Callable[[int], None] | None = None,
                               counterfactuals: bool = False) -> dict[str, float]:
        """Play ``demo_policy`` (anything with SB3's ``predict(obs, deterministic=True)``, e.g. the
        shelf heuristics) in the training env for ``n_steps`` steps of every sub-env and store its
        transitions as demonstrations: kept for the whole run, drawn as ``demo_fraction`` of each
        batch and trained with the margin loss. Episodes are cut where the steps run out; the env
        is reset before and after. Returns episodes, successes and steps played, and the
        counterfactual transitions stored.

        ``counterfactuals``: a demonstrator that tries actions in a copy of the env before acting
        (e.g. ``shelf_env``'s lookahead teachers) reports, through a ``counterfactuals()`` method
        called after each ``predict``, the actions it rejected because they end the episode, each
        as ``(action, reward, next_observation)``. They are kept as terminal transitions of the
        same state, with the TD loss only (not the margin loss, `add_demonstration`'s
        ``expert=False``): the learner then sees what the rejected action would have cost. One
        env only (the demonstrator probes that env).
        """
        if self.env is None:
            raise ValueError("collect_demonstrations needs the model's env; load the model with env=...")
        if n_steps < 1:
            raise ValueError(f"n_steps must be >= 1, got {n_steps}")
        space = getattr(demo_policy, "action_space", None)
        if space is not None and space != self.action_space:
            raise ValueError(
                f"demonstration policy {type(demo_policy).__name__} acts in {space} but the model's action "
                f"layout is {self.action_space} ({describe_layout(self.policy.maps)}): build it on the same env layout"
            )
        report: Any = getattr(demo_policy, "counterfactuals", None)
        if counterfactuals and not callable(report):
            raise ValueError(f"counterfactuals=True needs a demonstrator with a counterfactuals() method (one that "
                             f"tries actions before acting); {type(demo_policy).__name__} has none")
        if counterfactuals and self.env.num_envs != 1:
            raise ValueError(f"counterfactuals=True needs one env (the demonstrator probes it), the model has "
                             f"{self.env.num_envs}")
        buffer = self.replay_buffer
        assert isinstance(buffer, HindsightRelabelReplayBuffer)  # _setup_model checks the class
        env = self.env
        n_actions = int(self.action_space.n)
        capacity = capacity or 2 * n_steps * env.num_envs
        obs = np.asarray(env.reset())  # check_spaces allows Box observations only
        episodes = successes = stored = 0
        for step in range(n_steps):
            actions = np.asarray(demo_policy.predict(obs, deterministic=True)[0]).reshape(-1).astype(np.int64)
            if actions.shape != (env.num_envs,) or not ((actions >= 0) & (actions < n_actions)).all():
                raise ValueError(
                    f"demonstration policy {type(demo_policy).__name__} returned actions {actions.tolist()}; "
                    f"expected {env.num_envs} action(s) in [0, {n_actions})"
                )
            if counterfactuals:  # before the step: the same state, other actions
                for action, reward, next_obs in report():
                    self._check_counterfactual(demo_policy, action, next_obs, n_actions)
                    self._keep_rejected(obs, action, reward, next_obs, True, capacity)
                    stored += 1
            new_obs, rewards, dones, infos = env.step(actions)
            episodes += int(dones.sum())
            successes += sum(bool(info.get("is_success")) for done, info in zip(dones, infos) if done)
            buffer.add_demonstration(obs, self._final_observations(new_obs, dones, infos), actions, rewards, dones,
                                     infos, self._next_masks(new_obs, dones, infos), capacity=capacity)
            obs = np.asarray(new_obs)
            if progress is not None:
                progress(step + 1)
        self.demo_timesteps += n_steps * env.num_envs
        self._last_obs = env.reset()  # type: ignore[assignment]
        self._last_episode_starts = np.ones(env.num_envs, dtype=bool)
        return {"episodes": episodes, "successes": successes, "steps": n_steps * env.num_envs,
                "counterfactuals": stored}

    def _keep_rejected(self, obs: np.ndarray, action: int, reward: float, next_obs: Any, terminated: bool,
                       capacity: int) -> None:
        """Keep an action that was not taken in state ``obs`` (``(1, *obs_shape)``), with what it would
        have led to, in the demonstration store: TD loss only (``expert=False``); a non-terminal one
        with every next action allowed. A teacher's counterfactual or a correction's vetoed action."""
        buffer = self.replay_buffer
        assert isinstance(buffer, HindsightRelabelReplayBuffer)  # _setup_model checks the class
        buffer.add_demonstration(obs, np.asarray(next_obs)[None], np.array([action]),
                                 np.array([reward], dtype=np.float32), np.array([terminated]), [{}],
                                 capacity=capacity, expert=False)

    def _fits_layout(self, actions: Sequence[Any], next_obs: Any) -> bool:
        """Whether ``actions`` are integer actions of this model and ``next_obs`` has its observation shape."""
        n_actions = int(self.action_space.n)
        return all(isinstance(a, (int, np.integer)) and 0 <= int(a) < n_actions for a in actions) \
            and np.shape(next_obs) == self.observation_space.shape

    def _check_counterfactual(self, demo_policy: Any, action: Any, next_obs: Any, n_actions: int) -> None:
        """A clear error for a counterfactual that does not fit the model's layout."""
        shape = self.observation_space.shape
        if not self._fits_layout((action,), next_obs):
            raise ValueError(f"demonstrator {type(demo_policy).__name__} reported a counterfactual with action "
                             f"{action!r} and next observation of shape {np.shape(next_obs)}; expected an action in "
                             f"[0, {n_actions}) and shape {shape}")

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Greedy action (Eq. 1) if ``deterministic``, else ε-greedy (as SB3's DQN).

        ``action_masks`` is sb3-contrib's MaskablePPO convention: a bool array of
        ``action_space.n`` per observation, True = allowed, e.g. ``env.action_masks()`` or
        `get_action_masks` (env); the greedy and the exploratory action are then drawn among allowed
        actions only. When none is passed, nothing is masked — even if the model's env offers
        masks — exactly as MaskablePPO does: ``predict`` cannot know that ``observation`` is that
        env's current state. Pass the masks to act as the policy was trained to.
        """
        action, state = self.policy.predict(observation, state, episode_start, deterministic=True,
                                            action_masks=action_masks)
        if not deterministic:
            action = np.array(action, copy=True)
            flat = action.reshape(-1)
            explore = np.random.rand(flat.size) < self.exploration_rate
            if action_masks is None:
                flat[explore] = np.random.randint(int(self.action_space.n), size=int(explore.sum()))
            else:  # the policy's predict has validated them
                flat[explore] = self._exploratory_actions(explore, np.asarray(action_masks).reshape(flat.size, -1))
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
        return [*super()._excluded_save_params(), "q_net", "q_net_target", "_sample_rng", "_noop_history",
                "_use_masks", "_explore_masked", "_step_masks"]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        return ["policy", "policy.optimizer"], []

    def save(self, path: str | pathlib.Path | Any, exclude: Any = None, include: Any = None) -> None:
        """Save to ``path`` (``.zip`` added if it has no suffix) atomically: a crash leaves the old file intact."""
        if not isinstance(path, (str, pathlib.Path)):
            return super().save(path, exclude=exclude, include=include)
        write_atomically(
            _with_suffix(path, ".zip"), lambda tmp: super(PixelDoubleDQN, self).save(tmp, exclude, include)
        )

    def save_replay_buffer(self, path: str | pathlib.Path | Any) -> None:
        """Pickle the replay buffer (filled part only) to ``path`` (``.pkl`` added if no suffix), atomically."""
        if not isinstance(path, (str, pathlib.Path)):
            return super().save_replay_buffer(path)
        write_atomically(_with_suffix(path, ".pkl"), lambda tmp: super(PixelDoubleDQN, self).save_replay_buffer(tmp))

    @classmethod
    def load(
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
            model = super().load(path, env, device, custom_objects, print_system_info, force_reset, **kwargs)
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
        return model


def _with_suffix(path: str | pathlib.Path, suffix: str) -> pathlib.Path:
    path = pathlib.Path(path)
    return path if path.suffix else path.with_suffix(suffix)
