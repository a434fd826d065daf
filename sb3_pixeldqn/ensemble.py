"""`QEnsemble`: a greedy pixel policy that acts on the mean of several models' Q-maps.

Models trained by one recipe from one start on one dataset still differ with their seed (batch order,
augmentation draws), and at test time a greedy argmax turns small differences between Q-maps into
different actions. Averaging the members' Q-maps before the argmax keeps what they agree on and
damps what one seed got wrong: the standard output ensemble of value-based RL. It is not a weight
average (a "soup"): every member runs its own network, so it costs one forward pass per member.

- Members are `PixelDoubleDQN` models (or anything with the same ``policy``: `FCNPolicy`'s
  ``obs_to_tensor`` and ``all_q_values``) with one observation space, one action
  space and the same maps. Their raw Q-values are averaged with equal weights (or ``weights``), so
  members should share a value scale: the same reward, recipe and start.
- ``predict`` has SB3's signature with sb3-contrib's ``action_masks``: the argmax is over the allowed
  actions only, as `PixelDoubleDQN.predict` takes it. It is always greedy (``deterministic`` is
  accepted for the signature): an ensemble is a test-time policy, not a learner.
- It holds no memory; `LoopBreaker` can wrap it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces

from sb3_pixeldqn.policies import greedy_actions


class QEnsemble:
    """Greedy policy on the (weighted) mean of ``models``' Q-maps (see the module docstring).

    :param models: two or more pixel models with equal observation spaces, action spaces and maps.
    :param weights: one non-negative weight per model, not all zero (default: equal); normalised to sum 1.
    """

    def __init__(self, models: Sequence[Any], weights: Sequence[float] | None = None) -> None:
        models = list(models)
        if len(models) < 2:
            raise ValueError(f"QEnsemble needs at least two models, got {len(models)}")
        first = models[0]
        for k, model in enumerate(models):
            for attr in ("policy", "observation_space", "action_space"):
                if not hasattr(model, attr):
                    raise ValueError(f"ensemble member {k} ({type(model).__name__}) has no {attr}: "
                                     "members are PixelDoubleDQN models")
            if model.observation_space.shape != first.observation_space.shape:
                raise ValueError(f"ensemble member {k} observes {model.observation_space.shape}, member 0 "
                                 f"{first.observation_space.shape}")
            if not isinstance(model.action_space, spaces.Discrete) or model.action_space.n != first.action_space.n:
                raise ValueError(f"ensemble member {k} has action space {model.action_space}, member 0 "
                                 f"{first.action_space}")
            maps, first_maps = getattr(model.policy, "maps", None), getattr(first.policy, "maps", None)
            if maps != first_maps:
                raise ValueError(f"ensemble member {k} has Q-maps {maps}, member 0 {first_maps}")
        if weights is None:
            weights = [1.0] * len(models)
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (len(models),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError(f"weights must be {len(models)} finite non-negative numbers, not all zero; got "
                             f"{list(weights)}")
        self.models = models
        self.weights = w / w.sum()
        self.observation_space = first.observation_space
        self.action_space = first.action_space

    @property
    def acts_masked(self) -> bool:
        """Whether the ensemble acts within the env's masks: only if every member does."""
        return all(bool(getattr(m, "acts_masked", True)) for m in self.models)

    def q_values(self, observation: np.ndarray) -> th.Tensor:
        """The weighted mean of the members' Q-values, ``(B, n_actions)`` float32 (``B`` = 1 for one observation)."""
        total: th.Tensor | None = None
        for weight, model in zip(self.weights, self.models, strict=True):
            policy = model.policy
            policy.set_training_mode(False)
            obs_tensor, _ = policy.obs_to_tensor(observation)
            q = policy.all_q_values(obs_tensor).float().cpu()
            total = q * float(weight) if total is None else total + q * float(weight)
        assert total is not None  # at least two members
        return total

    def q_map_values(self, observation: np.ndarray) -> np.ndarray:
        """The mean Q-maps of one observation ``(C, H, W)`` -> ``(n_maps, H, W)``, or of a batch ->
        ``(B, n_maps, H, W)``: for looking at what the ensemble values; acting goes through `predict`."""
        obs = np.asarray(observation)
        single = obs.ndim == len(self.observation_space.shape)
        height, width = self.observation_space.shape[1:]
        q = self.q_values(obs).numpy().reshape(-1, int(self.action_space.n) // (height * width), height, width)
        return q[0] if single else q

    def predict(
        self,
        observation: np.ndarray,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Greedy action on the mean Q-maps for one observation ``(C, H, W)`` or a batch, within ``action_masks``."""
        obs = np.asarray(observation)
        single = obs.ndim == len(self.observation_space.shape)
        return greedy_actions(self.q_values(obs), action_masks, single), state
