"""The teacher dataset: labelled states of training scenes, for distilling a privileged teacher into the Q-maps.

A camera-only policy has to learn which actions drop an object and which make progress; the
episodes' own terminal rewards teach that too slowly (one fall per episode). Here every visited
state carries many labels, each the exact outcome of one masked action tried in a forked copy of
the simulator (`shelf_env.privileged.lookahead.probe_step`, or `probe_outcome` where the next image is not needed: the
same outcome without the copy's camera, about 40 % cheaper): did an object fall, did the scene stay valid,
how did the number of sorted objects change, did the step sort the scene. The labelled actions,
without repeats (at most ``max_probes``; past that only the teacher's and the greedy action): the
teacher's own probes (its chosen action among them), the driving model's greedy masked action, one
random graspable cell of every visible object, the teacher's push candidates, random masked actions.

The teacher is privileged (it reads the simulator): the one-step lookahead on H-d
(``h-d-lookahead``, `shelf_env.privileged.lookahead.LookaheadDistance`, the default: cheap, no value
estimate, so ``teacher_value`` is NaN) or the planning teacher (``h-d-planner``,
`shelf_env.privileged.planning.PlanningTeacher`: rollouts of the lookahead from each safe
candidate, about ten times the cost per state, with its best rollout's score as ``teacher_value``).
The executed action is the teacher's choice, or, with probability ``explore``, the model's greedy
action when its probe kept the scene valid, so the states cover where the learner goes too
(``explore`` = 1 with a distilled model as the driver: DAgger, the learner's own states labelled and its
falls rescued by the teacher). An
episode stops at its end (sorted, invalid, 40 actions) or when no probed action keeps the scene
valid.

Storage (one compressed ``.npz`` per shard, a shard = ``episodes_per_shard`` whole episodes,
written atomically, so a collection killed mid-shard leaves no partial shard): ``meta`` (JSON: the
format, the env's dynamics version, the observation layout, the teacher, the driving model's path and
sha256, ``explore``, per episode the reset
seed, N and the executed actions, and the wall-clock seconds the shard took), ``obs`` (S, C, H, W)
uint8, per state ``state_episode``, ``state_step``, ``teacher_action``, ``teacher_value``,
``executed_action``, and per label ``label_state`` (index into ``obs``), ``label_action``,
``label_valid``, ``label_fell``, ``label_success``, ``label_dsorted`` and ``label_source``
(`SOURCES`). Observations are stored, not only (seed, actions): PyBullet's episodes are
bit-identical on one machine but not across machines, so a replay elsewhere could see another
state than the one labelled. The seeds and actions are kept too (`replay_states` checks them on
the machine that collected them).

Scenes: training objects, reset seeds from `DATASET_SEED` (no evaluation draws from it), N uniform
over ``ns``. Commands (``python -m shelf_env.privileged.dataset -h``): ``collect`` (resumable, a wall-clock
budget, ``--workers K`` processes with shard series of their own) and ``status``.
"""

from __future__ import annotations

import argparse
import functools
import json
import multiprocessing
import os
import pathlib
import platform
import sys
import time
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pixeldqn.distill import LabelledStates
from sb3_pixeldqn.loop_breaker import predict_takes
from shelf_env import params
from shelf_env.actions import PRIMITIVES
from shelf_env.baselines.heuristics import ObservationView
from shelf_env.camera.heightmap import observation_masks
from shelf_env.env import DYNAMICS_VERSION
from shelf_env.evaluation.protocol import greedy_action, policy_digest, takes_action_masks
from shelf_env.files import write_atomically
from shelf_env.policies import POLICIES, make_policy, policy_file
from shelf_env.privileged.lookahead import LookaheadHeuristic, Outcome, probe_outcome
from shelf_env.processes import exit_with_parent, yield_cpu

#: Version of the shard layout below; a shard of another is refused.
FORMAT = 1
#: Seed of the dataset's scenes (`scene_seed`); no training run or evaluation draws from it.
DATASET_SEED = 9038
#: Where each label's action came from (``label_source``).
SOURCES = ("greedy", "teacher", "object", "push", "random")
#: Observation layout of the dataset: that of the shipped P+S (10 mm cells, pick + pushes).
PIXEL_SIZE = 0.01
DEFAULT_NS = tuple(range(3, 15))
STATE_KEYS = ("state_episode", "state_step", "teacher_action", "teacher_value", "executed_action")
EPISODE_STATE_KEYS = STATE_KEYS[1:]  # state_episode is numbered when the shard is saved
LABEL_KEYS = ("label_state", "label_action", "label_valid", "label_fell", "label_success", "label_dsorted",
              "label_source")


def scene_seed(series: int, shard: int, episode: int) -> int:
    """Reset seed of episode ``episode`` of shard ``shard`` of series ``series``."""
    return int(np.random.SeedSequence([DATASET_SEED, series, shard, episode]).generate_state(1)[0])


def shard_path(out: pathlib.Path, series: int, shard: int) -> pathlib.Path:
    return out / f"s{series:02d}_{shard:05d}.npz"


def layout(env: gym.Env) -> dict[str, Any]:
    """The observation layout a shard records and a reader checks."""
    base: Any = env.unwrapped
    return {"obs_shape": list(base.observation_space.shape), "pixel_size": float(base.camera.pixel_size),
            "map_names": list(base.codec.map_names)}


class Episode:
    """What one collected episode adds to a shard."""

    def __init__(self) -> None:
        self.obs: list[np.ndarray] = []
        self.states: dict[str, list[Any]] = {k: [] for k in EPISODE_STATE_KEYS}
        self.labels: dict[str, list[Any]] = {k: [] for k in LABEL_KEYS}
        self.actions: list[int] = []


def probe_actions(env: gym.Env, teacher: LookaheadHeuristic, view: ObservationView, greedy: int | None,
                  rng: np.random.Generator, max_probes: int) -> list[tuple[int, int]]:
    """``(action, source)`` to label beyond the teacher's own probes, in order (see the module docstring)."""
    codec = teacher.codec
    out: list[tuple[int, int]] = []
    if greedy is not None:
        out.append((greedy, SOURCES.index("greedy")))
    for b in rng.permutation(np.unique(view.blob[view.graspable])):
        rows, cols = np.nonzero(view.graspable & (view.blob == b))
        i = int(rng.integers(len(rows)))
        out.append((codec.encode("pick", int(rows[i]), int(cols[i])), SOURCES.index("object")))
    out += [(a, SOURCES.index("push")) for a in teacher.push_candidates(view)[:4]]
    allowed = np.flatnonzero(env.get_wrapper_attr("action_masks")())
    if len(allowed):
        out += [(int(a), SOURCES.index("random")) for a in rng.choice(allowed, size=min(3, len(allowed)),
                                                                      replace=False)]
    return out[:max_probes]


#: The teachers a collection may use (``--teacher``): registered policy names (`shelf_env.policies`).
TEACHERS = ("h-d-lookahead", "h-d-planner")


def collect_episode(env: gym.Env, model: Any, seed: int, rng: np.random.Generator, explore: float = 0.3,
                    max_probes: int = 24, teacher_name: str = "h-d-lookahead") -> Episode:
    """Play the scene of ``seed`` with the teacher and label every visited state (module docstring).
    ``model``: anything with SB3's ``predict(obs, deterministic, action_masks)``, whose greedy action is
    labelled first and sometimes executed; None for the teacher alone. It is asked as an evaluation asks
    (`shelf_env.evaluation.protocol.greedy_action`: the env's masks, and SB3's ``episode_start`` at the first
    state where its ``predict`` takes it), so a policy under wrappers with memory (the loop breaker, the pick
    guard) drives as it plays."""
    base: Any = env.unwrapped
    if teacher_name not in TEACHERS:
        raise ValueError(f"unknown teacher {teacher_name!r}; known: {list(TEACHERS)}")
    teacher: LookaheadHeuristic = POLICIES[teacher_name](env, 0)
    episode = Episode()
    masked = model is not None and takes_action_masks(model)
    starts = model is not None and predict_takes(model, "episode_start")
    obs, info = env.reset(seed=seed)
    sorted_now = int(info["num_sorted"])
    for step in range(base.max_actions):
        view = ObservationView.from_observation(obs, teacher.margin_cells)
        if not view.graspable.any():
            break
        greedy = None if model is None else greedy_action(env, model, obs, step == 0, masked, starts)
        choice = int(teacher.predict(obs, deterministic=True)[0])
        outcomes: dict[int, tuple[Outcome, int]] = {a: (o, SOURCES.index("teacher")) for a, o in teacher._probed}
        for action, source in probe_actions(env, teacher, view, greedy, rng, max_probes):
            if len(outcomes) >= max_probes and source != SOURCES.index("greedy"):
                break  # the greedy action (first) is labelled whatever the teacher's probes took
            if action in outcomes:
                if source == SOURCES.index("greedy"):  # the greedy label keeps its own source
                    outcomes[action] = (outcomes[action][0], source)
                continue
            outcomes[action] = (probe_outcome(env, action), source)
        if choice not in outcomes:
            outcomes[choice] = (probe_outcome(env, choice), SOURCES.index("teacher"))
        t = len(episode.obs)
        episode.obs.append(np.asarray(obs, dtype=np.uint8))
        for action, (outcome, source) in outcomes.items():
            labels = episode.labels
            labels["label_state"].append(t)
            labels["label_action"].append(action)
            labels["label_valid"].append(outcome.valid)
            labels["label_fell"].append(outcome.fell)
            labels["label_success"].append(outcome.is_success)
            labels["label_dsorted"].append(int(outcome.num_sorted or 0) - sorted_now)
            labels["label_source"].append(source)
        valid = [a for a, (o, _) in outcomes.items() if o.valid]
        executed = choice
        if greedy is not None and greedy in valid and rng.random() < explore:
            executed = greedy
        elif choice not in valid:
            executed = valid[int(rng.integers(len(valid)))] if valid else -1
        teacher_value = getattr(teacher, "value", None)
        row = (step, choice, np.nan if teacher_value is None else teacher_value, executed)
        for key, value in zip(EPISODE_STATE_KEYS, row):
            episode.states[key].append(value)
        if executed < 0:
            break  # nothing probed keeps the scene valid: no state after this one to show
        obs, _, terminated, truncated, info = env.step(executed)
        episode.actions.append(executed)
        sorted_now = int(info["num_sorted"])
        if terminated or truncated:
            break
    return episode


def save_shard(path: pathlib.Path, meta: dict[str, Any], episodes: list[Episode], obs_shape: Sequence[int]) -> None:
    """Write the shard's arrays to exactly ``path`` (`write_atomically` moves it into place)."""
    arrays: dict[str, np.ndarray] = {}
    obs = [o for ep in episodes for o in ep.obs]
    arrays["obs"] = np.stack(obs) if obs else np.zeros((0, *obs_shape), np.uint8)
    offset = 0
    states: dict[str, list[Any]] = {k: [] for k in STATE_KEYS}
    labels: dict[str, list[Any]] = {k: [] for k in LABEL_KEYS}
    for i, ep in enumerate(episodes):
        states["state_episode"] += [i] * len(ep.obs)
        for k in EPISODE_STATE_KEYS:
            states[k] += ep.states[k]
        for k in LABEL_KEYS:
            labels[k] += [s + offset for s in ep.labels[k]] if k == "label_state" else ep.labels[k]
        offset += len(ep.obs)
    dtypes = {"teacher_value": np.float32, "label_valid": bool, "label_fell": bool, "label_success": bool,
              "label_dsorted": np.int8, "label_source": np.uint8}
    for k, v in {**states, **labels}.items():
        arrays[k] = np.asarray(v, dtype=dtypes.get(k, np.int64))
    with open(path, "wb") as f:
        np.savez_compressed(f, meta=np.array(json.dumps(meta)), **arrays)  # type: ignore[arg-type]


@dataclass
class Shard:
    """One shard as read back (`load_shard`)."""

    path: pathlib.Path
    meta: dict[str, Any]
    arrays: dict[str, np.ndarray]

    @property
    def num_states(self) -> int:
        return len(self.arrays["obs"])

    @property
    def num_labels(self) -> int:
        return len(self.arrays["label_action"])


def load_shard(path: pathlib.Path, expect_layout: dict[str, Any] | None = None) -> Shard:
    """Read and check one shard; a truncated file, another format, another env dynamics version or (with
    ``expect_layout``) another observation layout is a `ValueError` that names the shard."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise ValueError(f"dataset shard {path}: unreadable (truncated or not a shard): {err}") from err
    if "meta" not in arrays:
        raise ValueError(f"dataset shard {path}: no meta entry (not a shard of this dataset)")
    meta = json.loads(str(arrays.pop("meta")))
    if meta.get("format") != FORMAT:
        raise ValueError(f"dataset shard {path}: format {meta.get('format')!r}, this version reads {FORMAT}")
    if meta.get("dynamics_version") != DYNAMICS_VERSION:
        raise ValueError(f"dataset shard {path}: collected with env dynamics version {meta.get('dynamics_version')!r}, "
                         f"this ShelfSort-v0 is version {DYNAMICS_VERSION}: its labels need not hold here")
    if expect_layout is not None and meta.get("layout") != expect_layout:
        raise ValueError(f"dataset shard {path}: observation layout {meta.get('layout')} is not {expect_layout}")
    missing = [k for k in ("obs", *STATE_KEYS, *LABEL_KEYS) if k not in arrays]
    if missing:
        raise ValueError(f"dataset shard {path}: missing arrays {missing}")
    if list(arrays["obs"].shape[1:]) != list(meta["layout"]["obs_shape"]):
        raise ValueError(f"dataset shard {path}: observations of shape {arrays['obs'].shape[1:]}, its meta says "
                         f"{meta['layout']['obs_shape']}")
    n_states, n_labels = len(arrays["obs"]), len(arrays["label_action"])
    if any(len(arrays[k]) != n_states for k in STATE_KEYS) or any(len(arrays[k]) != n_labels for k in LABEL_KEYS):
        raise ValueError(f"dataset shard {path}: per-state or per-label arrays of unequal lengths")
    if n_labels and (arrays["label_state"].min() < 0 or arrays["label_state"].max() >= n_states):
        raise ValueError(f"dataset shard {path}: a label points outside the shard's states")
    return Shard(path, meta, arrays)


def shard_files(folder: pathlib.Path) -> list[pathlib.Path]:
    return sorted(folder.glob("s[0-9][0-9]_[0-9][0-9][0-9][0-9][0-9].npz"))


def load_dataset(folder: pathlib.Path, expect_layout: dict[str, Any] | None = None) -> list[Shard]:
    """Every shard of ``folder``, checked (`load_shard`); a `ValueError` if there is none."""
    files = shard_files(folder)
    if not files:
        raise ValueError(f"no dataset shards (sNN_NNNNN.npz) in {folder}")
    return [load_shard(f, expect_layout) for f in files]


def replay_env(shard: Shard) -> gym.Env:
    """A ``ShelfSort-v0`` with the shard's object set, primitives and cell size, to replay its scenes in
    (``set_num_objects`` and ``reset(seed=...)`` per episode, then its executed actions)."""
    layout_ = shard.meta["layout"]
    primitives = ("pick", "push") if "push_left" in layout_["map_names"] else ("pick",)
    return gym.make("ShelfSort-v0", num_objects=1, object_set=shard.meta["object_set"], primitives=primitives,
                    pixel_size=layout_["pixel_size"])


def replay_states(shard: Shard, max_labels: int | None = None) -> tuple[int, int, list[str]]:
    """Replay a shard on this machine and check it: every state's observation against (reset seed,
    executed actions) and every label (up to ``max_labels``) against a real ``env.step`` of its action
    from that state. Returns ``(states checked, labels checked, mismatches)``; bit-identical only on the
    machine (and library build) that collected the shard."""
    env = replay_env(shard)
    a = shard.arrays
    mismatches: list[str] = []
    checked = 0
    try:
        for i, ep in enumerate(shard.meta["episodes"]):
            env.unwrapped.set_num_objects(ep["num_objects"])  # type: ignore[attr-defined]
            states = np.flatnonzero(a["state_episode"] == i)

            def state_at(t: int, ep: dict[str, Any] = ep) -> tuple[np.ndarray, int]:
                obs, info = env.reset(seed=ep["reset_seed"])
                for action in ep["actions"][:t]:
                    obs, _, _, _, info = env.step(action)
                return obs, int(info["num_sorted"])

            for s_index in states:
                obs, before = state_at(int(a["state_step"][s_index]))
                if not np.array_equal(obs, a["obs"][s_index]):
                    mismatches.append(f"state {s_index}: the replayed observation differs")
                for j, k in enumerate(np.flatnonzero(a["label_state"] == s_index)):
                    if max_labels is not None and checked >= max_labels:
                        break
                    if j:  # the previous label stepped the replay on: back to the state
                        state_at(int(a["state_step"][s_index]))
                    _, _, terminated, _, info = env.step(int(a["label_action"][k]))
                    valid = not terminated or bool(info["is_success"])
                    got = (valid, bool(info["fell"]), int(info["num_sorted"]) - before, bool(info["is_success"]))
                    want = (bool(a["label_valid"][k]), bool(a["label_fell"][k]), int(a["label_dsorted"][k]),
                            bool(a["label_success"][k]))
                    checked += 1
                    if got != want:
                        mismatches.append(f"label {k} (action {int(a['label_action'][k])}): stepped {got}, "
                                          f"stored {want}")
    finally:
        env.close()
    return len(a["obs"]), checked, mismatches


def labelled_states(shards: Sequence[Shard], invalid_reward: float = params.REWARD_INVALID,
                    masks: bool = True, progress: bool = True) -> LabelledStates:
    """The shards' states and labels in `sb3_pixeldqn.distill`'s form: an action that ended the episode
    invalid has the value ``invalid_reward``, one that sorted the scene ``params.REWARD_SORTED`` (both
    terminal, exact), any other an unknown value (NaN); the teacher's choice is the teacher action.
    ``masks``: each state's allowed actions, read from its observation (`observation_masks`, the env's
    own), so that distillation's teacher term ranges over the greedy policy's whole choice set.
    ``progress``: each label's change in the number of sorted objects is its progress score (a step that
    sorts an object ranks above one that changes nothing useful)."""
    parts = []
    offset = 0
    for shard in shards:
        a = shard.arrays
        value = np.full(len(a["label_action"]), np.nan, np.float32)
        value[~a["label_valid"]] = invalid_reward
        value[a["label_success"]] = params.REWARD_SORTED
        layout_ = shard.meta["layout"]
        packed = np.packbits(np.stack([observation_masks(o, layout_["pixel_size"], layout_["map_names"])
                                       for o in a["obs"]]), axis=1) if masks and len(a["obs"]) else None
        parts.append((a["obs"], a["label_state"] + offset, a["label_action"], ~a["label_valid"], value,
                      a["teacher_action"], packed, a["label_dsorted"].astype(np.float32)))
        offset += len(a["obs"])
    if not parts:
        raise ValueError("no shards to take labelled states from")
    obs, label_state, label_action, invalid, values, teacher = (np.concatenate([p[i] for p in parts])
                                                                for i in range(6))
    stacked = [p[6] for p in parts if p[6] is not None]
    return LabelledStates(obs, label_state, label_action, invalid, values, teacher,
                          masks=np.concatenate(stacked) if masks and stacked else None,
                          label_progress=np.concatenate([p[7] for p in parts]) if progress else None)


@dataclass
class Transitions:
    """The dataset's exact transitions, for a learner's kept demonstration store (`transitions`).
    ``next_state`` is -1 for a terminal transition (its next observation does not matter)."""

    obs: np.ndarray  # (S, C, H, W) uint8, the states of the shards in order
    state: np.ndarray  # (K,) int, index into obs
    next_state: np.ndarray  # (K,) int, index into obs, -1 where terminal
    action: np.ndarray  # (K,) int
    reward: np.ndarray  # (K,) float32
    done: np.ndarray  # (K,) bool
    expert: np.ndarray  # (K,) bool: the teacher's executed choice (the margin loss applies)

    def __len__(self) -> int:
        return len(self.action)


def transitions(shards: Sequence[Shard], invalid_reward: float = params.REWARD_INVALID,
                progress_reward: float = 0.0) -> Transitions:
    """What the shards know exactly, as (s, a, r, s', done) under the env's reward (Eq. 2, with the
    training env's ``invalid_reward`` and ``progress_reward``):

    - each executed action whose next state was stored: reward −1 (plus ``progress_reward`` per object
      it sorted), not terminal; ``expert`` where it was the teacher's choice (the rest were the driving
      model's greedy action, executed to cover its states: TD loss only);
    - every labelled action that ended the episode: invalid (``invalid_reward``) or sorting the scene
      (the goal's reward, 0), terminal, with the TD loss only (not the teacher's choice) unless it was
      the teacher's executed choice.

    Executed actions after which nothing was stored (the episode's time limit) and labelled actions
    that kept the episode going (their next state was not stored) are left out."""
    parts: list[tuple[np.ndarray, ...]] = []
    offset = 0
    for shard in shards:
        a = shard.arrays
        n = len(a["obs"])
        key = {(int(e), int(t)): i for i, (e, t) in enumerate(zip(a["state_episode"], a["state_step"]))}
        executed_label = {(int(s), int(act)): k for k, (s, act) in enumerate(zip(a["label_state"],
                                                                                  a["label_action"]))}
        rows: list[tuple[int, int, int, float, bool, bool]] = []
        for i in range(n):
            action = int(a["executed_action"][i])
            k = executed_label.get((i, action))
            if action < 0 or k is None:
                continue
            expert = action == int(a["teacher_action"][i])
            if a["label_valid"][k] and not a["label_success"][k]:
                after = key.get((int(a["state_episode"][i]), int(a["state_step"][i]) + 1))
                if after is not None:
                    reward = params.REWARD_STEP + progress_reward * int(a["label_dsorted"][k])
                    rows.append((i, after, action, reward, False, expert))
        for k in range(len(a["label_action"])):
            valid, success = bool(a["label_valid"][k]), bool(a["label_success"][k])
            if valid and not success:
                continue
            i, action = int(a["label_state"][k]), int(a["label_action"][k])
            expert = action == int(a["executed_action"][i]) == int(a["teacher_action"][i])
            rows.append((i, -1, action, params.REWARD_SORTED if success else invalid_reward, True, expert))
        if rows:
            cols = list(zip(*rows))
            state, nxt = np.array(cols[0]) + offset, np.array(cols[1])
            parts.append((state, np.where(nxt >= 0, nxt + offset, -1), np.array(cols[2]),
                          np.array(cols[3], np.float32), np.array(cols[4], bool), np.array(cols[5], bool)))
        offset += n
    if not shards:
        raise ValueError("no shards to take transitions from")
    obs = np.concatenate([s.arrays["obs"] for s in shards])
    if not parts:
        empty = np.zeros(0, np.int64)
        return Transitions(obs, empty, empty, empty, np.zeros(0, np.float32), np.zeros(0, bool), np.zeros(0, bool))
    return Transitions(obs, *(np.concatenate([p[i] for p in parts]) for i in range(6)))


def check_collection(hours: float, ns: Sequence[int], model_path: str | None, episodes_per_shard: int,
                     explore: float, max_probes: int, teacher: str) -> None:
    """`collect`'s arguments checked before anything runs: a `ValueError` naming the first bad one."""
    if hours <= 0:
        raise ValueError(f"hours must be > 0, got {hours}")
    if not ns or min(ns) < 1 or max(ns) > 14:
        raise ValueError(f"ns must be numbers of objects in 1..14, got {list(ns)}")
    if teacher not in TEACHERS:
        raise ValueError(f"unknown teacher {teacher!r}; known: {list(TEACHERS)}")
    if episodes_per_shard < 1 or max_probes < 1 or not 0 <= explore <= 1:
        raise ValueError("episodes_per_shard and max_probes must be >= 1 and explore in [0, 1]")
    if model_path is not None and not pathlib.Path(policy_file(model_path)).is_file():
        raise ValueError(f"driving model {policy_file(model_path)!r} does not exist")


def collect(out: pathlib.Path, series: int = 0, hours: float = 1.0, ns: Sequence[int] = DEFAULT_NS,
            model_path: str | None = "examples/pretrained/v1/p_s.zip", episodes_per_shard: int = 2,
            max_shards: int | None = None, explore: float = 0.3, max_probes: int = 24,
            object_set: str = "train", teacher: str = "h-d-lookahead") -> int:
    """Collect shards of series ``series`` into ``out`` until ``hours`` of wall clock have passed (a shard
    under way is finished first) or ``max_shards`` exist; shards on disk are skipped, so it resumes.
    Returns the number of shards written."""
    check_collection(hours, ns, model_path, episodes_per_shard, explore, max_probes, teacher)
    env = gym.make("ShelfSort-v0", num_objects=max(ns), object_set=object_set, primitives=PRIMITIVES,
                   pixel_size=PIXEL_SIZE)
    start, written, shard = time.monotonic(), 0, 0
    try:
        env_layout = layout(env)
        model, model_sha256 = None, None
        if model_path is not None:  # a checkpoint, with the wrappers it names (`shelf_env.policies.make_policy`)
            model, model_sha256 = make_policy(model_path, env), policy_digest(model_path)
        while max_shards is None or shard < max_shards:
            path = shard_path(out, series, shard)
            if path.exists():
                shard += 1
                continue
            if time.monotonic() - start > hours * 3600:
                break
            t0, episodes, metas = time.monotonic(), [], []
            for e in range(episodes_per_shard):
                seed = scene_seed(series, shard, e)
                rng = np.random.default_rng(seed)
                n = int(ns[int(rng.integers(len(ns)))])
                env.unwrapped.set_num_objects(n)  # type: ignore[attr-defined]
                ep = collect_episode(env, model, seed, rng, explore, max_probes, teacher)
                episodes.append(ep)
                metas.append({"reset_seed": seed, "num_objects": n, "actions": ep.actions})
            meta = {"format": FORMAT, "dynamics_version": DYNAMICS_VERSION, "layout": env_layout,
                    "object_set": object_set, "teacher": teacher, "model": model_path,
                    "model_sha256": model_sha256, "explore": explore,
                    "max_probes": max_probes, "series": series, "shard": shard, "episodes": metas,
                    "seconds": round(time.monotonic() - t0, 1), "machine": f"{platform.machine()}, "
                    f"{os.cpu_count()} CPUs", "collected": time.strftime("%Y-%m-%d")}
            write_atomically(path, functools.partial(save_shard, meta=meta, episodes=episodes,
                                                     obs_shape=env_layout["obs_shape"]))
            written += 1
            states, labels = sum(len(ep.obs) for ep in episodes), sum(len(ep.labels["label_action"])
                                                                        for ep in episodes)
            print(f"{path.name}: N={[m['num_objects'] for m in metas]}, {states} states, {labels} labels, "
                  f"{meta['seconds']:.0f} s", flush=True)
            shard += 1
    finally:
        env.close()
    return written


def _collect_worker(kwargs: dict[str, Any]) -> int:
    import torch

    torch.set_num_threads(1)
    return collect(**kwargs)


def select_shards(shards: Sequence[Shard], spec: int | str | None, option: str = "--max-shards") -> list[Shard]:
    """The shards a run uses, so that a growing dataset's past can be named: all (None), the first ``spec``
    in name order (a number), or the first k of each series listed (``"s00:55,s01:9"``, as `status` prints it;
    other series left out). A series listed with fewer shards than asked is refused; ``option`` names the
    argument in that error."""
    if spec is None:
        return list(shards)
    if isinstance(spec, int) or str(spec).isdigit():
        return list(shards[:int(spec)])
    wanted: dict[str, int] = {}
    for part in str(spec).split(","):
        name, _, digits = part.strip().partition(":")
        if not (len(name) == 3 and name[0] == "s" and name[1:].isdigit() and digits.isdigit()):
            raise ValueError(f"{option} takes a number or 's00:55,s01:9', got {spec!r}")
        wanted[name] = int(digits)
    out: list[Shard] = []
    for name, count in wanted.items():
        own = [s for s in shards if s.path.name.startswith(name + "_")][:count]
        if len(own) < count:
            raise ValueError(f"{option} asks for {count} shards of series {name}; the dataset holds {len(own)}")
        out += own
    return sorted(out, key=lambda s: s.path.name)


@dataclass
class DatasetSummary:
    """What `summarize` counts: per N ``[scenes, states, labels, invalid labels]``, per series ``[shards, states,
    labels, seconds]`` (each shard's own clock), and the ``--max-shards`` spec, the series with a missing shard, the
    newest shard's date and the shards' size on disk, all read from the whole dataset even where ``since`` leaves
    shards out."""

    folder: pathlib.Path
    since: str | None
    shards: int
    per_n: dict[int, list[int]]
    per_series: dict[str, list[float]]
    spec: str
    gaps: list[str]
    collected: str | None  # the newest shard's collection date (YYYY-MM-DD); None where no shard records one
    size_bytes: int  # the read shard files' size on disk: the whole dataset, whatever since leaves out

    @property
    def states(self) -> int:
        return int(sum(r[1] for r in self.per_series.values()))

    @property
    def labels(self) -> int:
        return int(sum(r[2] for r in self.per_series.values()))

    @property
    def seconds(self) -> float:
        return float(sum(r[3] for r in self.per_series.values()))


def summarize(folder: pathlib.Path, since: str | None = None, names: set[str] | None = None) -> DatasetSummary:
    """Count what the dataset in ``folder`` holds (see `status`); ``since``: count only the shards after that spec;
    ``names``: only these shard files count as the dataset (e.g. the ones git tracks while a collector adds more)."""
    if names is None:
        every = load_dataset(folder)
    else:
        every = [load_shard(f) for f in shard_files(folder) if f.name in names]
        if not every:
            raise ValueError(f"none of the {len(names)} named shards is in {folder}")
    before = {s.path.name for s in select_shards(every, since, "--since")} if since is not None else set()
    shards = [s for s in every if s.path.name not in before]
    per_n: dict[int, list[int]] = {}
    per_series: dict[str, list[float]] = {}
    for s in shards:
        row_s = per_series.setdefault(s.path.name.partition("_")[0], [0, 0, 0, 0.0])
        row_s[0] += 1
        row_s[1] += s.num_states
        row_s[2] += s.num_labels
        row_s[3] += float(s.meta["seconds"])
        episode_n = np.array([e["num_objects"] for e in s.meta["episodes"]])
        n_of_state = episode_n[s.arrays["state_episode"]]
        n_of_label = n_of_state[s.arrays["label_state"]]
        for n in np.unique(episode_n):
            row = per_n.setdefault(int(n), [0, 0, 0, 0])
            row[0] += int((episode_n == n).sum())
            row[1] += int((n_of_state == n).sum())
            row[2] += int((n_of_label == n).sum())
            row[3] += int((~s.arrays["label_valid"][n_of_label == n]).sum())
    count: dict[str, int] = {}  # the spec and the gap check read the whole dataset, with or without since
    last: dict[str, int] = {}
    for s in every:
        name, _, index = s.path.stem.partition("_")
        count[name] = count.get(name, 0) + 1
        last[name] = max(last.get(name, 0), int(index) + 1)  # shards 0..k-1 unless one is missing
    dates = [str(s.meta["collected"]) for s in every if "collected" in s.meta]
    return DatasetSummary(folder=folder, since=since, shards=len(shards), per_n=per_n, per_series=per_series,
                          spec=",".join(f"{name}:{k}" for name, k in sorted(count.items())),
                          gaps=[name for name, k in sorted(count.items()) if last[name] != k],
                          collected=max(dates) if dates else None,
                          size_bytes=sum(s.path.stat().st_size for s in every))


def status(folder: pathlib.Path, since: str | None = None) -> str:
    """What the dataset holds: states, labels and scenes per N and per series, label outcomes, the collection's
    throughput (per series from each shard's own clock), and the ``--max-shards`` spec that names today's dataset
    for a run that must stay reproducible while the dataset grows (`select_shards`). ``since``: an earlier such
    spec; the tables then count only the shards collected after it (a session's collection and its rates), while
    the spec line still names all of it."""
    return format_status(summarize(folder, since))


def format_status(d: DatasetSummary) -> str:
    """`status`'s text for a `summarize` result."""
    states, labels, seconds = d.states, d.labels, d.seconds

    def per_hour(count: float, secs: float) -> str:
        return f"{count / max(secs, 1e-9) * 3600:.0f}"

    lines = [f"dataset {d.folder}{f' since {d.since}' if d.since is not None else ''}: {d.shards} shards, "
             f"{sum(r[0] for r in d.per_n.values())} scenes, {states} states, "
             f"{labels} labels ({labels / max(states, 1):.1f} per state), "
             f"{sum(r[3] for r in d.per_n.values()) / max(labels, 1):.1%} of labels invalid",
             f"collection: {seconds / 3600:.2f} h of worker time, {per_hour(states, seconds)} states "
             f"and {per_hour(labels, seconds)} labels per worker-hour",
             "| N | scenes | states | labels | invalid labels |", "|---|---|---|---|---|"]
    lines += [f"| {n} | {r[0]} | {r[1]} | {r[2]} | {r[3] / max(r[2], 1):.1%} |" for n, r in sorted(d.per_n.items())]
    lines += ["", "| series | shards | states | labels | worker-hours | states / labels per worker-hour |",
              "|---|---|---|---|---|---|"]
    lines += [f"| {name} | {r[0]:.0f} | {r[1]:.0f} | {r[2]:.0f} | {r[3] / 3600:.2f} | "
              f"{per_hour(r[1], r[3])} / {per_hour(r[2], r[3])} |" for name, r in sorted(d.per_series.items())]
    lines.append(f"all of it, named for a reproducible run: --max-shards {d.spec}")
    if d.gaps:  # a collection fills a missing shard first, so the first k of such a series can change
        lines.append("series with a missing shard (the spec names them only until it is collected): "
                     + ", ".join(d.gaps))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m shelf_env.privileged.dataset", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    c = sub.add_parser("collect", help="collect shards until a wall-clock budget is spent (resumable)")
    c.add_argument("--out", type=pathlib.Path, default=pathlib.Path("data/teacher"), help="the dataset folder")
    c.add_argument("--hours", type=float, default=1.0, help="wall-clock budget; a shard under way is finished")
    c.add_argument("--workers", type=int, default=1, help="processes, each with its own shard series (16 on a "
                   "16-core machine)")
    c.add_argument("--series", type=int, default=0, help="first shard series (worker k uses series + k)")
    c.add_argument("--ns", type=int, nargs="+", default=list(DEFAULT_NS), help="numbers of objects to draw from")
    c.add_argument("--model", default="examples/pretrained/v1/p_s.zip", help="driving model whose greedy action is "
                   "labelled first, a checkpoint with any wrappers shelf-evaluate takes (the shipped P+S: "
                   "examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker); 'none' for the teacher alone")
    c.add_argument("--episodes-per-shard", type=int, default=2, help="whole episodes per shard file")
    c.add_argument("--max-shards", type=int, default=None, help="stop once each series holds this many shards")
    c.add_argument("--max-probes", type=int, default=24, help="most labelled actions per state")
    c.add_argument("--explore", type=float, default=0.3, help="probability of executing the driving model's greedy "
                   "action where its probe kept the scene valid (1: follow the model, the teacher only rescuing its "
                   "falls, as in DAgger)")
    c.add_argument("--teacher", choices=TEACHERS, default="h-d-lookahead", help="the privileged teacher whose choice "
                   "is executed and labelled")
    c.add_argument("--nice", type=int, default=10, help="lower the collection's CPU priority by this much (0..19; "
                   "with its own session's group where it leads one: shelf_env.processes.yield_cpu), so that it "
                   "runs beside other work; 0 leaves it")
    s = sub.add_parser("status", help="print what the dataset holds")
    s.add_argument("folder", type=pathlib.Path, nargs="?", default=pathlib.Path("data/teacher"),
                   help="the dataset folder")
    s.add_argument("--since", default=None, help="count only the shards after these, a spec as the last line "
                   "prints it (s03:436,s05:244): one session's collection and its throughput")
    args = parser.parse_args(argv)
    try:
        if args.command == "status":
            print(status(args.folder, args.since))
            return 0
        if args.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {args.workers}")
        model_path = None if args.model == "none" else args.model
        check_collection(args.hours, args.ns, model_path, args.episodes_per_shard, args.explore, args.max_probes,
                         args.teacher)
        jobs = [{"out": args.out, "series": args.series + k, "hours": args.hours, "ns": tuple(args.ns),
                 "model_path": model_path, "episodes_per_shard": args.episodes_per_shard,
                 "max_shards": args.max_shards, "max_probes": args.max_probes, "teacher": args.teacher,
                 "explore": args.explore} for k in range(args.workers)]
        yield_cpu(args.nice)  # once the arguments hold, before any worker starts: they inherit it
        if args.workers == 1:
            written = [_collect_worker(jobs[0])]
        else:
            with multiprocessing.get_context("spawn").Pool(args.workers, initializer=exit_with_parent,
                                                           initargs=(os.getpid(),)) as pool:
                written = pool.map(_collect_worker, jobs)
        print(f"wrote {sum(written)} shards into {args.out}")
    except ValueError as err:
        print(f"dataset: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
