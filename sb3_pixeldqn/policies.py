"""`FCNPolicy`: online and target pixel-wise Q-networks with a map layout, and argmax action selection.

The action space is ``Discrete(n_maps * H * W)`` with ``a = m * H * W + row * W + col`` over an
image observation ``Box(0, 255, (C, H, W), uint8)``. Each map ``m`` is one FCN seen through one
input rotation (§IV-B.1b); ``maps`` lists them as ``(network_name, degrees)`` pairs, and maps that
share a network name share its weights. The default is the paper's P+S layout — pick, push at 0°,
push at 180° — and ``maps=[("pick", 0)]`` is the pick-only variant S.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from sb3_pixeldqn.networks import DEFAULT_WIDTHS, SUPPORTED_ROTATIONS, ResidualFCN, rotate

MapLayout = tuple[tuple[str, int], ...]

#: The paper's P+S layout (§IV-C): pick-and-place, push left (0°), push right (180°).
PICK_AND_PUSH_MAPS: MapLayout = (("pick", 0), ("push", 0), ("push", 180))
#: The pick-only layout of the S baseline.
PICK_ONLY_MAPS: MapLayout = (("pick", 0),)
#: Batch chunk of the no-grad passes (measured on 2 cores: 16 ~ 8 < 32 for a batch-32 P+S step).
DEFAULT_NO_GRAD_CHUNK = 16
#: Paper's Adam weight decay (§IV-D.3).
DEFAULT_WEIGHT_DECAY = 2e-5


def describe_layout(maps: MapLayout) -> str:
    return "[" + ", ".join(f"{name}@{deg}" for name, deg in maps) + "]"


def check_map_layout(maps: Sequence[Sequence[Any]]) -> MapLayout:
    """Normalise ``maps`` to a tuple of (name, degrees) and reject unknown rotations or duplicates."""
    try:
        layout = tuple((str(name), int(deg)) for name, deg in maps)
    except (TypeError, ValueError) as err:
        raise ValueError(f"maps must be a sequence of (network_name, degrees) pairs, got {maps!r}") from err
    if not layout:
        raise ValueError("maps must name at least one Q-map")
    for name, deg in layout:
        if deg not in SUPPORTED_ROTATIONS:
            raise ValueError(f"map {name}@{deg}: rotation must be one of {SUPPORTED_ROTATIONS}")
    if len(set(layout)) != len(layout):
        raise ValueError(f"maps {describe_layout(layout)} lists the same (network, rotation) twice")
    return layout


class PixelQNetwork(nn.Module):
    """One FCN per network name; Q-maps for the layout's (network, rotation) pairs.

    ``q_maps`` computes every map (used for argmax), ``q_values_at`` only the map each sample needs
    (used for the executed action and for the target net), so no FCN runs on a sample it does not
    have to.
    """

    def __init__(self, in_channels: int, maps: MapLayout, widths: tuple[int, int, int]) -> None:
        super().__init__()
        self.maps = maps
        names = list(dict.fromkeys(name for name, _ in maps))
        self.fcns = nn.ModuleDict({name: ResidualFCN(in_channels, widths) for name in names})

    def _run(self, name: str, views: list[tuple[th.Tensor, int]]) -> list[th.Tensor]:
        """One FCN pass over several rotated views stacked along the batch; Q-maps rotated back."""
        stacked = th.cat([rotate(images, degrees) for images, degrees in views])
        if stacked.dim() == 4 and stacked.stride(1) == 1:  # keep channels-last inputs channels-last
            stacked = stacked.contiguous(memory_format=th.channels_last)
        q = self.fcns[name](stacked)
        sizes = [images.shape[0] for images, _ in views]
        return [rotate(part, -degrees % 360) for part, (_, degrees) in zip(q.split(sizes), views)]

    def q_maps(self, images: th.Tensor) -> th.Tensor:
        """All Q-maps, ``(B, n_maps, H, W)``. Each network runs once on all its rotations stacked."""
        out: list[th.Tensor] = [images.new_empty(0)] * len(self.maps)
        for name in self.fcns:
            indices = [i for i, (n, _) in enumerate(self.maps) if n == name]
            for i, q in zip(indices, self._run(name, [(images, self.maps[i][1]) for i in indices])):
                out[i] = q
        return th.stack(out, dim=1)

    def q_values_at(self, images: th.Tensor, map_index: th.Tensor, pixel_index: th.Tensor) -> th.Tensor:
        """Q(images[b], map_index[b], pixel_index[b]) for each b, running each sample only through
        the map it needs; all samples of one network go through it in a single pass."""
        parts, order = [], []
        for name in self.fcns:
            rows_per_map, views = [], []
            for m, (n, degrees) in enumerate(self.maps):
                if n != name:
                    continue
                rows = th.nonzero(map_index == m, as_tuple=True)[0]
                if rows.numel():
                    rows_per_map.append(rows)
                    views.append((images[rows], degrees))
            if not views:
                continue
            for rows, q in zip(rows_per_map, self._run(name, views)):
                parts.append(q.flatten(1).gather(1, pixel_index[rows].unsqueeze(1)).squeeze(1))
                order.append(rows)
        values = th.cat(parts)
        return values[th.argsort(th.cat(order))]


class FCNPolicy(BasePolicy):
    """Online and target `PixelQNetwork`; ``_predict`` is the argmax over all maps and pixels (Eq. 1).

    :param observation_space: ``Box(0, 255, (C, H, W), uint8)``, channel-first.
    :param action_space: ``Discrete(len(maps) * H * W)``.
    :param lr_schedule: learning-rate schedule (from the algorithm).
    :param maps: the Q-map layout, ``(network_name, degrees)`` per map, in action order.
    :param widths: channel widths of the FCN's three resolution levels.
    :param no_grad_chunk: batch chunk for passes without gradients (argmax on s', target values).
    :param channels_last: run the FCNs in channels-last memory layout (faster convolutions on CPU).
    :param optimizer_kwargs: defaults to the paper's ``weight_decay=2e-5``.
    """

    q_net: PixelQNetwork
    q_net_target: PixelQNetwork
    observation_space: spaces.Box
    action_space: spaces.Discrete

    def __init__(
        self,
        observation_space: spaces.Box,
        action_space: spaces.Discrete,
        lr_schedule: Schedule,
        maps: Sequence[tuple[str, int]] = PICK_AND_PUSH_MAPS,
        widths: tuple[int, int, int] = DEFAULT_WIDTHS,
        no_grad_chunk: int = DEFAULT_NO_GRAD_CHUNK,
        channels_last: bool = True,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
    ) -> None:
        if optimizer_kwargs is None:
            optimizer_kwargs = {"weight_decay": DEFAULT_WEIGHT_DECAY}
        self.maps = check_map_layout(maps)
        check_spaces(observation_space, action_space, self.maps)
        super().__init__(
            observation_space,
            action_space,
            features_extractor=None,
            normalize_images=normalize_images,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
        )
        if len(widths) != 3:
            raise ValueError(f"widths must be three channel counts (one per residual stage), got {widths!r}")
        self.widths = (int(widths[0]), int(widths[1]), int(widths[2]))
        if no_grad_chunk < 1:
            raise ValueError(f"no_grad_chunk must be >= 1, got {no_grad_chunk}")
        self.no_grad_chunk = int(no_grad_chunk)
        self.channels_last = bool(channels_last)
        self.image_shape = tuple(observation_space.shape[1:])
        self._build(lr_schedule)

    def _build(self, lr_schedule: Schedule) -> None:
        in_channels = self.observation_space.shape[0]
        self.q_net = PixelQNetwork(in_channels, self.maps, self.widths)
        self.q_net_target = PixelQNetwork(in_channels, self.maps, self.widths)
        self.q_net_target.load_state_dict(self.q_net.state_dict())
        self.q_net_target.requires_grad_(False)
        self.q_net_target.train(False)
        if self.channels_last:
            # torch's stubs lack Module.to's memory_format keyword, which torch documents and accepts
            self.q_net.to(memory_format=th.channels_last)  # type: ignore[call-overload]
            self.q_net_target.to(memory_format=th.channels_last)  # type: ignore[call-overload]
        self.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.q_net.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )

    @property
    def n_maps(self) -> int:
        return len(self.maps)

    def images(self, obs: PyTorchObs) -> th.Tensor:
        """uint8 observations -> float images in [0, 1] in the FCN's memory layout."""
        assert isinstance(obs, th.Tensor)
        images = obs.float()
        if self.normalize_images:
            images = images / 255.0
        if self.channels_last:
            images = images.contiguous(memory_format=th.channels_last)
        return images

    def all_q_maps(self, net: PixelQNetwork, images: th.Tensor) -> th.Tensor:
        """Every Q-map of ``net`` without gradients, ``(B, n_maps, H, W)``, in chunks of ``no_grad_chunk``."""
        with th.no_grad():
            return th.cat([net.q_maps(chunk) for chunk in images.split(self.no_grad_chunk)])

    def q_map_values(self, observation: np.ndarray) -> np.ndarray:
        """The online Q-maps of one observation ``(C, H, W)`` -> ``(n_maps, H, W)``, or of a batch
        ``(B, C, H, W)`` -> ``(B, n_maps, H, W)``, as float32 numpy: for looking at what the network
        values (demos, TensorBoard images); acting goes through `predict`."""
        self.set_training_mode(False)
        obs_tensor, vectorized = self.obs_to_tensor(observation)
        assert isinstance(obs_tensor, th.Tensor)  # check_spaces allows Box observations only
        q = self.all_q_maps(self.q_net, self.images(obs_tensor)).float().cpu().numpy()
        return q if vectorized else q[0]

    def q_values_at(self, net: PixelQNetwork, images: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """Q of each sample's action (flat index) under ``net``; gradients flow only if ``net`` has them."""
        map_index, pixel_index = self.split_actions(actions)
        return net.q_values_at(images, map_index, pixel_index)

    def split_actions(self, actions: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """Flat action ``m * H * W + pixel`` -> (map index, pixel index)."""
        pixels = self.image_shape[0] * self.image_shape[1]
        actions = actions.long().reshape(-1)
        return actions // pixels, actions % pixels

    def forward(self, obs: PyTorchObs, deterministic: bool = True) -> th.Tensor:
        return self._predict(obs, deterministic=deterministic)

    def _predict(
        self, observation: PyTorchObs, deterministic: bool = True, action_masks: th.Tensor | None = None
    ) -> th.Tensor:
        return masked_argmax(self.all_q_values(observation), action_masks)

    def all_q_values(self, observation: PyTorchObs) -> th.Tensor:
        """Every online Q-value of each observation, ``(B, n_maps * H * W)`` in action order, without gradients."""
        return self.all_q_maps(self.q_net, self.images(observation)).flatten(1)

    def predict(
        self,
        observation: np.ndarray | dict[str, np.ndarray],
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
        action_masks: np.ndarray | None = None,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        """Greedy action (Eq. 1) for one observation ``(C, H, W)`` or a batch ``(B, C, H, W)``.

        ``action_masks`` (sb3-contrib's convention): a bool array of ``action_space.n`` (or
        ``(B, action_space.n)``), True = allowed; the argmax is taken over allowed actions only.
        None: over every map and pixel, as in the paper.
        """
        self.set_training_mode(False)
        obs_tensor, vectorized_env = self.obs_to_tensor(observation)
        assert isinstance(obs_tensor, th.Tensor)  # check_spaces allows Box observations only
        return greedy_actions(self.all_q_values(obs_tensor), action_masks, not vectorized_env), state

    def q_for_loss(
        self, images: th.Tensor, actions: th.Tensor, full_rows: th.Tensor
    ) -> tuple[th.Tensor, th.Tensor]:
        """Online Q of each sample's executed action, with gradients, and the full Q-maps
        ``(n_full, n_maps * H * W)`` of the rows in ``full_rows`` (bool), also with gradients.

        Rows without ``full_rows`` run only their executed map (Eq. 3); the others run every map
        once, and their executed value is read from those maps (the large-margin loss of
        demonstrations needs them all).
        """
        q = images.new_empty(images.shape[0])
        partial = ~full_rows
        if partial.any():
            q[partial] = self.q_values_at(self.q_net, images[partial], actions[partial])
        full = images.new_empty((0, int(self.action_space.n)))
        if full_rows.any():
            full = self.q_net.q_maps(images[full_rows]).flatten(1)
            q[full_rows] = full.gather(1, actions[full_rows].long().reshape(-1, 1)).squeeze(1)
        return q, full

    def set_training_mode(self, mode: bool) -> None:
        self.q_net.train(mode)
        self.training = mode

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            maps=self.maps,
            widths=self.widths,
            no_grad_chunk=self.no_grad_chunk,
            channels_last=self.channels_last,
            lr_schedule=self._dummy_schedule,
            optimizer_class=self.optimizer_class,
            optimizer_kwargs=self.optimizer_kwargs,
        )
        return data


def masked_argmax(q: th.Tensor, action_masks: th.Tensor | None) -> th.Tensor:
    """Row-wise argmax of ``q`` ``(B, n)`` over the actions ``action_masks`` allows (all if None).

    A row whose mask allows nothing falls back to all actions; callers that take masks from users
    reject such masks before (`check_action_masks`).
    """
    if action_masks is None:
        return q.argmax(dim=1)
    masks = action_masks.reshape(q.shape).to(dtype=th.bool, device=q.device)
    masks = masks | ~masks.any(dim=1, keepdim=True)
    return q.masked_fill(~masks, -th.inf).argmax(dim=1)


def greedy_actions(q: th.Tensor, action_masks: Any, single: bool) -> np.ndarray:
    """``predict``'s answer from Q-values ``q`` ``(B, n)``: the argmax over the actions the user's ``action_masks``
    allow (checked by `check_action_masks`; None: all), an int array ``(B,)``, or a 0-d array for one
    observation (``single``). `FCNPolicy.predict` answers with it, and so do test-time policies that combine
    Q-maps (`sb3_pixeldqn.QEnsemble`)."""
    masks = None
    if action_masks is not None:
        masks = th.as_tensor(check_action_masks(action_masks, int(q.shape[1]), int(q.shape[0])), device=q.device)
    actions = masked_argmax(q, masks).cpu().numpy().reshape((-1,))
    return actions.squeeze(axis=0) if single else actions


def check_action_masks(action_masks: Any, n_actions: int, batch: int) -> np.ndarray:
    """``action_masks`` as a ``(batch, n_actions)`` bool array, or a ValueError that names the problem:
    wrong dtype (it must be bool, True = allowed), wrong length, or a row that allows no action."""
    masks = np.asarray(action_masks)
    if masks.dtype != np.bool_:
        raise ValueError(f"action_masks must be a bool array (True = allowed), got dtype {masks.dtype}")
    if masks.size != batch * n_actions:
        raise ValueError(
            f"action_masks has shape {masks.shape}; expected ({n_actions},) per observation "
            f"({batch} observation(s), action_space.n = {n_actions})"
        )
    masks = masks.reshape(batch, n_actions)
    empty = np.flatnonzero(~masks.any(axis=1))
    if empty.size:
        raise ValueError(f"action_masks allows no action for observation(s) {empty.tolist()}")
    return masks


def check_spaces(observation_space: spaces.Space, action_space: spaces.Space, maps: MapLayout) -> None:
    """Raise a ValueError that names the problem if the spaces do not fit the map layout."""
    if not isinstance(observation_space, spaces.Box) or len(observation_space.shape) != 3:
        raise ValueError(
            f"FCNPolicy needs a channel-first image observation space Box(0, 255, (C, H, W), uint8); "
            f"got {observation_space}"
        )
    if observation_space.dtype != np.uint8:
        raise ValueError(f"FCNPolicy needs uint8 image observations; got dtype {observation_space.dtype}")
    if not isinstance(action_space, spaces.Discrete):
        raise ValueError(f"FCNPolicy needs a Discrete(n_maps * H * W) action space; got {action_space}")
    _, height, width = observation_space.shape
    expected = len(maps) * height * width
    if int(action_space.n) != expected:
        raise ValueError(
            f"action space Discrete({int(action_space.n)}) does not match the Q-map layout "
            f"{describe_layout(maps)}: {len(maps)} maps x {height} x {width} pixels = {expected} actions. "
            f"Pass policy_kwargs=dict(maps=...) with one (network, degrees) pair per map of the env "
            f"(e.g. maps=[('pick', 0)] for a pick-only env)."
        )
