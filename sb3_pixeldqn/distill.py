"""Distillation: a supervised loss on every labelled pixel of a state, for `FCNPolicy`'s Q-maps.

Reinforcement learning gives a Q-map one pixel of gradient per transition (Eq. 3). A teacher that
can try many actions from one state (in simulation, where a state can be copied) says much more:
which of those actions end the episode and with what value, and which one it would take. This
module trains the online Q-network on such labelled states; the algorithm and the network stay
the paper's, and `PixelDoubleDQN.learn` can fine-tune the result as usual.

A labelled state (`LabelledStates`): an observation and any number of labelled actions, each with

- ``invalid``: the action ends the episode invalid (in a shelf: an object falls out);
- ``value``: its exact value where the action ends the episode (the invalid reward, or the reward of
  reaching the goal), NaN where the label does not know it;

- ``progress`` (optional): a score of what the action achieved where it kept the episode going (for
  a shelf: the change in the number of sorted objects);

and, optionally, the teacher's action in that state (one of its labelled actions). The loss of a
batch of states is the sum of four terms, each over every labelled pixel:

- **value**: Huber(Q(s, a), value) on the labels with a known value;
- **ranking**: every action that kept the episode valid is valued at least ``margin`` above every
  action that ended it invalid, in the same state: mean relu(Q(s, a_inv) + margin − Q(s, a_ok));
- **progress**: among the actions of one state that kept the episode valid, one with a higher
  ``progress`` is valued at least ``margin`` above one with a lower: mean relu(Q(s, a_lo) + margin −
  Q(s, a_hi)). It is what tells a step that sorts an object from a valid step that changes nothing
  useful (picking an object already in its region and putting it back there), which the other
  terms leave level: without it a distilled policy can avoid every fall and still loop. With
  ``progress_radius`` r > 0 the lower action stands for the allowed cells of its map within r cells
  (the best of them is pushed below the higher action): a useless pick is useless at every cell of its
  object, and pushing down the one labelled pixel leaves its neighbours to be the next greedy choice;
- **teacher**: the large-margin loss of demonstrations on the teacher's action: max_a [Q(s, a) +
  margin·(a ≠ a_T)] − Q(s, a_T), over every action the state's mask allows where the states carry
  masks (``masks``: the greedy policy's own choice set, so the teacher's action is taught to be its
  argmax), over the labelled actions otherwise. Without masks a pixel no label covers is never
  pushed down, and the greedy argmax over thousands of them can land on a safe but useless one.
  With ``teacher_radius`` r > 0 the teacher's action stands for the cells of its map within r cells
  of it (a square): the best of them must beat every allowed action outside it by the margin,
  relu(max_out Q + margin − max_near Q). A teacher means "this object" more than "this pixel", and a
  fully convolutional map can hardly raise one pixel a margin above its neighbours on the same
  object: with r = 0 the term's largest competitor is nearly always such a neighbour, and it
  teaches nothing about which object to move. With ``teacher_set`` the teacher's choice stands for a
  set: its action and every labelled action of the state that kept the episode valid with a
  ``progress`` at least the teacher's, where the teacher's is positive (each with its square). A
  teacher breaks ties among equally good actions by its own order; without the set, each of those
  ties is pushed down as if it were worse.

It knows nothing of shelves: actions are flat indices of the policy's maps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch as th
import torch.nn.functional as F

#: Weights of the value, ranking, teacher and progress terms.
Weights = tuple[float, float, float, float]
DEFAULT_WEIGHTS: Weights = (1.0, 1.0, 1.0, 1.0)


@dataclass(frozen=True)
class LossOptions:
    """How `distillation_loss` reads a batch's labels (module docstring): one value for training, evaluation
    and a run's report, instead of the same five arguments threaded through every layer.

    - ``margin``: the ranking, progress and teacher terms' margin;
    - ``weights``: of the value, ranking, teacher and progress terms;
    - ``teacher_radius``: the teacher's action stands for its map's cells within that many cells (0: the pixel);
    - ``progress_radius``: the lower action of a progress pair stands for the allowed cells of its map within
      that many cells (0: the pixel);
    - ``teacher_temperature`` > 0: the teacher term as a cross-entropy at that temperature (0: the margin);
    - ``teacher_set``: the teacher's action stands for itself and every labelled action of its state as good by
      the labels (valid, progress at least the teacher's where the teacher's is positive; module docstring).

    Refuses negative or non-finite values by name."""

    margin: float = 1.0
    weights: Weights = DEFAULT_WEIGHTS
    teacher_radius: int = 0
    progress_radius: int = 0
    teacher_temperature: float = 0.0
    teacher_set: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "weights", tuple(float(w) for w in self.weights))
        for name in ("margin", "teacher_radius", "progress_radius", "teacher_temperature"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")
        for name in ("teacher_radius", "progress_radius"):
            if int(getattr(self, name)) != getattr(self, name):
                raise ValueError(f"{name} must be a whole number of cells, got {getattr(self, name)}")
        if not isinstance(self.teacher_set, bool):
            raise ValueError(f"teacher_set must be True or False, got {self.teacher_set!r}")
        if len(self.weights) != 4:
            raise ValueError(f"weights must be 4 numbers (value, ranking, teacher, progress), got {self.weights}")
        for term, w in zip(("value", "ranking", "teacher", "progress"), self.weights):
            if not (math.isfinite(w) and w >= 0):
                raise ValueError(f"the {term} weight must be a finite number >= 0, got {w}")


@dataclass
class LabelledStates:
    """States and their labelled actions (see the module docstring); ``label_state`` indexes ``obs``."""

    obs: np.ndarray  # (S, C, H, W) uint8
    label_state: np.ndarray  # (K,) int
    label_action: np.ndarray  # (K,) int, flat action index
    label_invalid: np.ndarray  # (K,) bool
    label_value: np.ndarray  # (K,) float, NaN where unknown
    teacher_action: np.ndarray  # (S,) int, -1 where none
    #: (S, ceil(n_actions / 8)) uint8: each state's allowed actions, ``np.packbits`` along axis 1; None: no masks
    masks: np.ndarray | None = None
    #: (K,) float: each label's progress score (see the module docstring); None: no progress term
    label_progress: np.ndarray | None = None
    _index: tuple[np.ndarray, np.ndarray] | None = field(default=None, init=False, repr=False, compare=False)

    def check(self, obs_shape: tuple[int, ...], n_actions: int) -> None:
        """A `ValueError` naming what does not fit the policy's observation and action spaces."""
        if self.obs.dtype != np.uint8 or tuple(self.obs.shape[1:]) != tuple(obs_shape):
            raise ValueError(f"labelled states: observations {self.obs.dtype} {self.obs.shape[1:]}, the policy "
                             f"takes uint8 {tuple(obs_shape)}")
        k = len(self.label_action)
        if not (len(self.label_state) == len(self.label_invalid) == len(self.label_value) == k):
            raise ValueError("labelled states: per-label arrays of unequal lengths")
        if len(self.teacher_action) != len(self.obs):
            raise ValueError("labelled states: teacher_action needs one entry per state")
        if k and (self.label_state.min() < 0 or self.label_state.max() >= len(self.obs)):
            raise ValueError("labelled states: a label points outside the states")
        if k and (self.label_action.min() < 0 or self.label_action.max() >= n_actions):
            raise ValueError(f"labelled states: a labelled action outside [0, {n_actions})")
        if (self.teacher_action >= n_actions).any():
            raise ValueError(f"labelled states: a teacher action outside [0, {n_actions})")
        if self.label_progress is not None and len(self.label_progress) != k:
            raise ValueError("labelled states: label_progress needs one entry per label")
        if self.masks is not None and self.masks.shape != (len(self.obs), (n_actions + 7) // 8):
            raise ValueError(f"labelled states: masks of shape {self.masks.shape}, expected "
                             f"{(len(self.obs), (n_actions + 7) // 8)} (packed bits of {n_actions} actions per state)")

    def unpacked_masks(self, n_actions: int) -> np.ndarray | None:
        """The masks as (S, n_actions) bool, None where the states carry none."""
        if self.masks is None:
            return None
        return np.unpackbits(self.masks, axis=1, count=n_actions).astype(bool)

    def labels_of(self) -> tuple[np.ndarray, np.ndarray]:
        """The labels sorted by state (a stable order) and where each state's run of them starts
        (``starts[s]:starts[s + 1]``): built once, so that `subset` touches only the labels it takes."""
        if self._index is None:
            order = np.argsort(self.label_state, kind="stable")
            starts = np.concatenate([[0], np.cumsum(np.bincount(self.label_state, minlength=len(self.obs)))])
            self._index = (order, starts)
        return self._index

    def subset(self, states: np.ndarray) -> LabelledStates:
        """The states ``states`` (indices) and their labels, renumbered; costs the size of the subset,
        not of the whole data (a training batch is one)."""
        states = np.asarray(states, dtype=np.int64)
        order, starts = self.labels_of()
        counts = starts[states + 1] - starts[states]
        rows = np.concatenate([order[starts[i]:starts[i + 1]] for i in states]) if len(states) else order[:0]
        return LabelledStates(self.obs[states], np.repeat(np.arange(len(states)), counts), self.label_action[rows],
                              self.label_invalid[rows], self.label_value[rows], self.teacher_action[states],
                              None if self.masks is None else self.masks[states],
                              None if self.label_progress is None else self.label_progress[rows])

def augmented(data: LabelledStates, transforms: Sequence[Any], n_actions: int,
              rng: np.random.Generator) -> LabelledStates:
    """``data`` with every state drawn through ``transforms`` (`PixelDoubleDQN`'s ``augment``: callables
    ``(obs, action, next_obs, next_mask, rng)``, e.g. exact symmetries of the env): one draw per state,
    applied alike to its observation, its labelled actions and its teacher action (each call gets a
    generator seeded the same, so a random transform makes the same choice for all of them)."""
    if not transforms:
        return data
    obs = data.obs.copy()
    actions = data.label_action.copy()
    teacher = data.teacher_action.copy()
    masks = data.unpacked_masks(n_actions)
    full = np.ones(n_actions, dtype=bool)

    def apply(o: np.ndarray, action: int, seed: int, mask: np.ndarray = full) -> tuple[np.ndarray, int, np.ndarray]:
        draw = np.random.default_rng(seed)
        for transform in transforms:  # a state's mask goes where a transition's next mask goes: moved alike
            o, action, _, mask = transform(o, action, o, mask, draw)
        return o, int(action), mask

    order, starts = data.labels_of()
    for s in range(len(obs)):
        seed = int(rng.integers(2**63))
        for k in order[starts[s]:starts[s + 1]]:
            actions[k] = apply(data.obs[s], int(data.label_action[k]), seed)[1]
        if teacher[s] >= 0:
            teacher[s] = apply(data.obs[s], int(teacher[s]), seed)[1]
        obs[s], _, mask = apply(data.obs[s], 0, seed, full if masks is None else masks[s])
        if masks is not None:
            masks[s] = mask
    packed = None if masks is None else np.packbits(masks, axis=1)
    return LabelledStates(obs, data.label_state, actions, data.label_invalid, data.label_value, teacher, packed,
                          data.label_progress)


def near_cells(actions: th.Tensor, grid: Sequence[int], radius: int) -> th.Tensor:
    """(R, n_actions) bool: for each flat action of ``actions`` (R,), the actions of the same map within
    ``radius`` cells of it in rows and columns (a square); ``grid`` = (n_maps, H, W)."""
    n_maps, height, width = (int(g) for g in grid)
    index = th.arange(n_maps * height * width, device=actions.device)
    m, r, c = index // (height * width), index // width % height, index % width
    am, ar, ac = actions // (height * width), actions // width % height, actions % width
    return ((m[None] == am[:, None]) & ((r[None] - ar[:, None]).abs() <= radius)
            & ((c[None] - ac[:, None]).abs() <= radius))


def teacher_sets(rows: th.Tensor, label_state: th.Tensor, label_action: th.Tensor, invalid: th.Tensor,
                 progress: th.Tensor, teacher: th.Tensor, n_actions: int, grid: Sequence[int] | None = None,
                 radius: int = 0) -> th.Tensor:
    """(R, n_actions) bool: for each state of ``rows`` (R,) the labelled actions as good as its teacher's by the
    labels, each with its square of ``radius`` cells (``grid`` = (n_maps, H, W), needed where ``radius`` > 0):
    valid, with a progress at least that of the teacher's own label, where that progress is positive. A state
    whose teacher's action is unlabelled, invalid or made no progress gets none (its teacher's action alone)."""
    n_states = int(teacher.shape[0])
    is_teacher = (label_action == teacher[label_state]) & ~invalid
    bar = th.full((n_states,), th.inf, dtype=progress.dtype, device=progress.device)
    bar[label_state[is_teacher]] = progress[is_teacher]  # the teacher's progress, +inf where it has no label
    bar = th.where(bar > 0, bar, th.full_like(bar, th.inf))  # no progress: no set
    row_of = th.full((n_states,), -1, dtype=th.long, device=rows.device)
    row_of[rows] = th.arange(len(rows), device=rows.device)
    good = ~invalid & (progress >= bar[label_state]) & (row_of[label_state] >= 0)
    actions = label_action[good]
    if radius > 0:
        assert grid is not None
        cells = near_cells(actions, grid, radius)
    else:
        cells = F.one_hot(actions, n_actions).bool()
    counts = th.zeros((len(rows), n_actions), device=rows.device)
    return counts.index_add_(0, row_of[label_state[good]], cells.to(counts.dtype)) > 0


def distillation_loss(q_maps: th.Tensor, label_state: th.Tensor, label_action: th.Tensor, invalid: th.Tensor,
                      value: th.Tensor, teacher: th.Tensor, options: LossOptions = LossOptions(),
                      masks: th.Tensor | None = None, progress: th.Tensor | None = None,
                      grid: Sequence[int] | None = None) -> tuple[th.Tensor, dict[str, float]]:
    """The loss of a batch (module docstring) under ``options``: ``q_maps`` (B, n_actions) with gradients,
    labels indexing its rows; ``teacher`` (B,) with -1 where a state has none; ``masks`` (B, n_actions) bool,
    the allowed actions the teacher term ranges over (None: the labelled actions); ``progress`` (K,) the
    labels' progress scores (None: no progress term); ``grid`` = (n_maps, H, W), the layout of the flat
    actions, which a teacher or progress radius > 0 needs to place its square. With
    ``options.progress_radius`` > 0 the best allowed cell near a pair's lower action must lie a margin below
    the higher action. With ``options.teacher_temperature`` > 0 the teacher term is a cross-entropy instead
    of a margin: the softmax of Q / temperature over the allowed actions should put its mass on the
    teacher's action (its square), logsumexp(allowed) − logsumexp(teacher's cells), a gradient on every
    allowed action rather than on the two extremes. ``options.teacher_set`` (needs ``progress``) widens the
    teacher's cells to the set of `teacher_sets`. Returns the loss and its terms."""
    margin, teacher_radius, progress_radius = options.margin, options.teacher_radius, options.progress_radius
    teacher_temperature = options.teacher_temperature
    if options.teacher_set and progress is None:
        raise ValueError("teacher_set needs the labels' progress scores to tell which actions are as good as the "
                         "teacher's; got none")
    for name, radius in (("teacher_radius", teacher_radius), ("progress_radius", progress_radius)):
        if radius > 0 and grid is None:
            raise ValueError(f"{name} > 0 needs the grid of the flat actions to place its square; got {radius} "
                             f"and no grid")
    qa = q_maps[label_state, label_action]
    zero = q_maps.sum() * 0.0
    known = ~th.isnan(value)
    value_loss = F.smooth_l1_loss(qa[known], value[known]) if known.any() else zero
    same = label_state[:, None] == label_state[None, :]
    pairs = same & ~invalid[:, None] & invalid[None, :]  # (valid row, invalid column) of one state
    ranking = F.relu(qa[None, :] + margin - qa[:, None])[pairs].mean() if pairs.any() else zero
    progress_loss = zero
    if progress is not None:
        ahead = same & ~invalid[:, None] & ~invalid[None, :] & (progress[:, None] > progress[None, :])
        if ahead.any():  # (higher row, lower column) of one state, both valid
            low = qa
            if progress_radius > 0:  # the lower action's neighbourhood: the best allowed cell near it
                assert grid is not None
                n_maps, height, width = (int(g) for g in grid)
                shown = q_maps if masks is None else th.where(masks, q_maps, th.full_like(q_maps, -th.inf))
                pooled = F.max_pool2d(shown.view(-1, n_maps, height, width), 2 * progress_radius + 1, stride=1,
                                      padding=progress_radius).flatten(1)
                low = th.maximum(pooled[label_state, label_action], qa)
            progress_loss = F.relu(low[None, :] + margin - qa[:, None])[ahead].mean()
    teacher_loss = zero
    is_teacher = label_action == teacher[label_state]
    rows = th.unique(label_state[(teacher[label_state] >= 0) & is_teacher])
    if len(rows):
        t = teacher[rows]
        at = th.arange(len(rows), device=q_maps.device)
        if masks is not None:  # over every allowed action of the state
            allowed = masks[rows].clone()
        else:  # over the state's labelled actions
            allowed = th.zeros((len(rows), q_maps.shape[1]), dtype=th.bool, device=q_maps.device)
            member = label_state[None, :] == rows[:, None]  # (R, K)
            hit = member.nonzero()
            allowed[hit[:, 0], label_action[hit[:, 1]]] = True
        allowed[at, t] = True
        if teacher_radius > 0:
            assert grid is not None
            near = near_cells(t, grid, teacher_radius)
        else:
            near = th.zeros_like(allowed)
            near[at, t] = True
        if options.teacher_set:
            assert progress is not None
            near = near | teacher_sets(rows, label_state, label_action, invalid, progress, teacher, near.shape[1],
                                       grid, teacher_radius)
        q_rows = q_maps[rows]
        none = th.full_like(q_rows, -th.inf)
        if teacher_temperature > 0:
            logits = q_rows / teacher_temperature
            teacher_loss = (th.where(allowed, logits, none).logsumexp(dim=1)
                            - th.where(allowed & near, logits, none).logsumexp(dim=1)).mean()
        else:
            q_near = th.where(allowed & near, q_rows, none).max(dim=1).values
            q_out = th.where(allowed & ~near, q_rows, none).max(dim=1).values
            teacher_loss = F.relu(q_out + margin - q_near).mean()
    w_value, w_ranking, w_teacher, w_progress = options.weights
    loss = w_value * value_loss + w_ranking * ranking + w_teacher * teacher_loss + w_progress * progress_loss
    return loss, {"value": float(value_loss.detach()), "ranking": float(ranking.detach()),
                  "teacher": float(teacher_loss.detach()), "progress": float(progress_loss.detach())}


def batch_loss(policy: Any, data: LabelledStates, states: np.ndarray,
               options: LossOptions) -> tuple[th.Tensor, dict[str, float], th.Tensor, LabelledStates]:
    """`distillation_loss` of the states ``states`` of ``data`` under ``policy``'s online network, with their
    Q-maps ``(B, n_maps, H, W)`` and the subset they index."""
    sub = data.subset(states)
    device = policy.device
    q_maps = policy.q_net.q_maps(policy.images(th.as_tensor(sub.obs, device=device)))
    q = q_maps.flatten(1)
    label_state = th.as_tensor(sub.label_state, device=device)
    label_action = th.as_tensor(sub.label_action, device=device)
    masks = sub.unpacked_masks(q.shape[1])
    loss, parts = distillation_loss(q, label_state, label_action, th.as_tensor(sub.label_invalid, device=device),
                                    th.as_tensor(sub.label_value, dtype=th.float32, device=device),
                                    th.as_tensor(sub.teacher_action, device=device), options,
                                    None if masks is None else th.as_tensor(masks, device=device),
                                    None if sub.label_progress is None else
                                    th.as_tensor(sub.label_progress, dtype=th.float32, device=device),
                                    tuple(q_maps.shape[1:]))
    return loss, parts, q_maps, sub


def evaluate(policy: Any, data: LabelledStates, options: LossOptions = LossOptions(),
             chunk: int = 32) -> dict[str, float]:
    """The mean loss (under ``options``) and its terms over every state of ``data`` (no gradients), and how often the
    network's best labelled action of a state is one that ended the episode invalid (``invalid_choice``:
    the greedy choice among the labelled actions) and, where the states carry masks, how often its masked
    argmax over every action is the teacher's action (``teacher_choice``) and, with ``teacher_radius`` > 0,
    lies within ``options.teacher_radius`` cells of it on its map (``teacher_near``, where that radius is > 0),
    and, where the labels carry progress, how often it lies in the teacher's square or the square of a labelled
    action as good (``teacher_set_choice``: `teacher_sets`, whether or not the loss uses them)."""
    teacher_radius = options.teacher_radius
    totals: dict[str, float] = {"loss": 0.0, "value": 0.0, "ranking": 0.0, "teacher": 0.0, "progress": 0.0}
    invalid_choices = chosen = agree = near = in_set = taught = 0
    policy.set_training_mode(False)
    with th.no_grad():
        for start in range(0, len(data.obs), chunk):
            states = np.arange(start, min(start + chunk, len(data.obs)))
            loss, parts, q_maps, sub = batch_loss(policy, data, states, options)
            totals["loss"] += float(loss) * len(states)
            for key, v in parts.items():
                totals[key] += v * len(states)
            q_np = q_maps.flatten(1).cpu().numpy()
            qa = q_np[sub.label_state, sub.label_action]
            masks = sub.unpacked_masks(q_np.shape[1])
            if masks is not None:
                has = sub.teacher_action >= 0
                greedy = np.where(masks, q_np, -np.inf).argmax(axis=1)
                agree += int((greedy[has] == sub.teacher_action[has]).sum())
                taught += int(has.sum())
                if has.any():  # the teacher's square (its pixel where the radius is 0), once for both counts
                    rows = np.flatnonzero(has)
                    teacher_t = th.as_tensor(sub.teacher_action)
                    square = (near_cells(teacher_t[rows], q_maps.shape[1:], teacher_radius) if teacher_radius > 0
                              else F.one_hot(teacher_t[rows], q_np.shape[1]).bool())
                    picked = np.arange(len(rows)), greedy[rows]
                    if teacher_radius > 0:
                        near += int(square.numpy()[picked].sum())
                    if sub.label_progress is not None:
                        good = square | teacher_sets(th.as_tensor(rows), th.as_tensor(sub.label_state),
                                                     th.as_tensor(sub.label_action), th.as_tensor(sub.label_invalid),
                                                     th.as_tensor(sub.label_progress), teacher_t, q_np.shape[1],
                                                     q_maps.shape[1:], teacher_radius)
                        in_set += int(good.numpy()[picked].sum())
            for s in range(len(states)):
                rows = np.flatnonzero(sub.label_state == s)
                if len(rows):
                    invalid_choices += int(sub.label_invalid[rows[int(np.argmax(qa[rows]))]])
                    chosen += 1
    out = {k: v / max(len(data.obs), 1) for k, v in totals.items()}
    out["invalid_choice"] = invalid_choices / max(chosen, 1)
    if taught:
        out["teacher_choice"] = agree / taught
        if teacher_radius > 0:
            out["teacher_near"] = near / taught
        if data.label_progress is not None:
            out["teacher_set_choice"] = in_set / taught
    return out


def distill(model: Any, data: LabelledStates, epochs: int = 1, batch_states: int = 16,
            options: LossOptions = LossOptions(), seed: int = 0, augment: Sequence[Any] = (), anchor: float = 0.0,
            anchor_net: Any = None) -> list[dict[str, float]]:
    """Train ``model``'s online Q-network (a `PixelDoubleDQN`) on ``data`` for ``epochs`` passes with its own
    optimiser, then copy it to the target network. ``augment``: transforms each batch's states are drawn
    through (`augmented`; ``model.augment`` for the model's own). ``anchor`` > 0 adds that weight times
    the **anchor** term: Huber(Q(s, a), Q_0(s, a)) over every allowed action of a state that no label
    covers, Q_0 being ``anchor_net`` (a frozen copy of the starting Q-network, e.g. made once before the
    first call): the labels move the actions they speak of, the rest of the map keeps what the
    starting model had learned (which objects to move, in which order). ``options``: the loss's margin,
    weights, radii and temperature (`LossOptions`). Returns each epoch's mean training loss and terms."""
    policy = model.policy
    data.check(tuple(model.observation_space.shape), int(model.action_space.n))
    if epochs < 1 or batch_states < 1:
        raise ValueError(f"epochs and batch_states must be >= 1, got {epochs} and {batch_states}")
    if anchor < 0 or (anchor > 0 and anchor_net is None):
        raise ValueError(f"anchor must be >= 0, and > 0 only with an anchor_net; got {anchor} and {anchor_net!r:.40}")
    rng = np.random.default_rng(seed)
    history = []
    for _ in range(epochs):
        policy.set_training_mode(True)
        sums: dict[str, float] = {"loss": 0.0, "value": 0.0, "ranking": 0.0, "teacher": 0.0, "progress": 0.0,
                                  "anchor": 0.0}
        order = rng.permutation(len(data.obs))
        for start in range(0, len(order), batch_states):
            batch = data.subset(order[start:start + batch_states])
            batch = augmented(batch, augment, int(model.action_space.n), rng)
            states = np.arange(len(batch.obs))
            loss, parts, q_maps, sub = batch_loss(policy, batch, states, options)
            q = q_maps.flatten(1)
            if anchor > 0:
                assert anchor_net is not None
                with th.no_grad():
                    q0 = anchor_net.q_maps(policy.images(th.as_tensor(sub.obs, device=policy.device))).flatten(1)
                masks = sub.unpacked_masks(q.shape[1])
                free = th.ones_like(q, dtype=th.bool) if masks is None else th.as_tensor(masks, device=q.device)
                free[th.as_tensor(sub.label_state), th.as_tensor(sub.label_action)] = False
                anchor_loss = F.smooth_l1_loss(q[free], q0[free]) if free.any() else q.sum() * 0.0
                loss = loss + anchor * anchor_loss
                parts["anchor"] = float(anchor_loss.detach())
            policy.optimizer.zero_grad(set_to_none=True)
            loss.backward()
            policy.optimizer.step()
            sums["loss"] += float(loss.detach()) * len(states)
            for key, v in parts.items():
                sums[key] += v * len(states)
        history.append({k: v / len(order) for k, v in sums.items()})
    model.q_net_target.load_state_dict(model.q_net.state_dict())
    policy.set_training_mode(False)
    return history
