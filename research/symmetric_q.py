"""``<zip>+symmetric``: a pixel Q-policy acting on its Q-maps averaged over the cabinet's exact symmetries.

`shelf_env.symmetry` names two symmetries of `ShelfSort-v0`: the mirror across the cabinet's width
and the renaming of the three classes. Together they form a group of 2 x 3! = 12 elements. A
perfect Q-function is equivariant under it (the mirrored scene's value map is the mirrored value
map; a scene with renamed classes has the same value map). A trained network is so only
approximately; the distillation trains it on randomly transformed states, so its twelve views of
one scene are twelve noisy estimates of the same values. `SymmetricQ` evaluates all twelve and
acts greedily on their mean, mapped back to the scene's own frame:

    Q̄(s) = 1/12 Σ_g g⁻¹ · Q(g · s)

The mean is exactly equivariant (``tests/test_symmetric_q.py``): the greedy action in a mirrored
scene is the mirror of the greedy action, and renaming the classes changes nothing. It reads only
the observation (a camera-only policy) and costs 12 network passes per decision, batched.

It is an experiment (docs/experiments/symmetric-q.md): it registers ``+symmetric`` with
`shelf_env.policies` when imported, so ``python -m research.evaluate --policies X.zip+symmetric``
plays it.
"""

from __future__ import annotations

import itertools
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th

from sb3_pixeldqn.policies import greedy_actions
from shelf_env import policies
from shelf_env.actions import ActionCodec
from shelf_env.camera.heightmap import CLASS_RGB
from shelf_env.symmetry import MirrorWidth, PermuteClasses

#: The wrapper's suffix in policy names.
SYMMETRIC = "+symmetric"


class SymmetricQ:
    """Greedy on ``model``'s Q-maps averaged over the cabinet's symmetries (see the module docstring).

    :param model: a `PixelDoubleDQN` (anything whose ``policy.q_map_values`` maps a batch of
        observations ``(B, C, H, W)`` to Q-maps ``(B, n_maps, H, W)``).
    :param codec: the env's action codec (`ActionCodec.of`), for the mirror's map permutation.
    :param mirror: average over the width mirror.
    :param permutations: average over the 3! class renamings.
    """

    def __init__(self, model: Any, codec: ActionCodec, mirror: bool = True, permutations: bool = True) -> None:
        q_map_values = getattr(getattr(model, "policy", None), "q_map_values", None)
        if not callable(q_map_values):
            raise ValueError(f"SymmetricQ averages Q-maps; {type(model).__name__} has no policy.q_map_values")
        self.model = model
        self.action_space = model.action_space
        self.observation_space = model.observation_space
        if len(codec.map_names) * codec.rows * codec.cols != int(self.action_space.n):
            raise ValueError(f"{type(model).__name__}'s {self.action_space.n} actions are not the env's "
                             f"{len(codec.map_names)} maps of {codec.rows}x{codec.cols}")
        self._mirror = MirrorWidth(codec, p=1.0) if mirror else None
        self._permute = PermuteClasses()
        identity = tuple(range(len(CLASS_RGB)))
        self.perms = list(itertools.permutations(identity)) if permutations else [identity]

    @classmethod
    def for_env(cls, model: Any, env: gym.Env, **kwargs: Any) -> SymmetricQ:
        """``model`` acting in a ShelfSort-v0 ``env`` (through wrappers)."""
        return cls(model, ActionCodec.of(env), **kwargs)

    @property
    def acts_masked(self) -> bool:
        """Whether the wrapped model acts with the env's masks (`shelf_env.evaluation.protocol.takes_action_masks`)."""
        return bool(getattr(self.model, "acts_masked", True))

    @property
    def n_views(self) -> int:
        """Network passes per decision."""
        return len(self.perms) * (2 if self._mirror is not None else 1)

    def q_maps(self, observation: np.ndarray) -> np.ndarray:
        """The mean Q-maps ``(n_maps, H, W)`` of one observation ``(C, H, W)`` over its views."""
        obs = np.asarray(observation)
        views = [self._permute.observation(obs, p) for p in self.perms]
        if self._mirror is not None:
            views += [self._mirror.observation(v) for v in views]
        q = self.model.policy.q_map_values(np.stack(views)).astype(np.float64)
        plain = q[:len(self.perms)].mean(axis=0)
        if self._mirror is None:
            return plain
        # a mirrored view's action a is the scene's mirror(a): its mean maps back once (the map is linear)
        mirrored = self._mirror.mask(q[len(self.perms):].mean(axis=0).reshape(-1)).reshape(plain.shape)
        return (plain + mirrored) / 2

    def predict(
        self,
        observation: np.ndarray,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """The masked argmax of the mean Q-maps, for one observation ``(C, H, W)`` or a batch; always greedy."""
        obs = np.asarray(observation)
        single = obs.ndim == len(self.observation_space.shape)
        batch = obs[None] if single else obs
        q = th.as_tensor(np.stack([self.q_maps(o).reshape(-1) for o in batch]))
        return greedy_actions(q, action_masks, single), state


policies.register_wrapper(SYMMETRIC, lambda agent, env, base: SymmetricQ.for_env(agent, env))
