"""Policies by name: the registry that evaluations, the demo and the CLI build every policy from.

A policy is named by a string: a registered name (`register_policy`: ``"h-d"``, ``"h-a"``,
``"random"``, the privileged ``"h-d-lookahead"``, ``"h-a-lookahead"`` and ``"h-d-planner"``) or the path of a
`PixelDoubleDQN` zip (P+S or S; the env layout follows the checkpoint), followed by any registered
wrappers (`register_wrapper`), innermost first: ``"examples/pretrained/p_s.zip+loop-breaker"``
plays the checkpoint under `sb3_pixeldqn.LoopBreaker`. A wrapper changes what the policy does, so
results with it get cells and labels of their own (`policy_label`: ``p_s+loop-breaker``). A leading
``LABEL=`` names the policy's results LABEL instead of the checkpoint's file stem
(``"mine=runs/a/model.zip+loop-breaker"`` -> ``mine+loop-breaker``), so that two runs' ``model.zip`` can be
evaluated side by side. A ``NAME.ensemble.json`` file (`write_ensemble`) names two or more checkpoints that act
as one `sb3_pixeldqn.ensemble.QEnsemble` (greedy on the mean of their Q-maps); its label is ``NAME``.

The product registers its own names, the loop breaker and the geometry pick filter (``+geometry-filter``,
`shelf_env.fall_filter`) here; an experiment registers its own
wrappers when it is imported (``research/fall_risk.py`` registers ``+fall-filter``), and the product
never imports an experiment. `check_policy` validates a name before any work starts.
"""

from __future__ import annotations

import json
import os
import pathlib
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pixeldqn.loop_breaker import LoopBreaker
from shelf_env import params
from shelf_env.baselines.heuristics import AccessibilityHeuristic, DistanceHeuristic, RandomPolicy
from shelf_env.fall_filter import GEOMETRY_FILTER, FallFilter, GeometryRisk, geometry_risk_path
from shelf_env.files import write_json_atomically
from shelf_env.pick_guard import PICK_GUARD, PickGuard
from shelf_env.privileged.lookahead import LookaheadAccessibility, LookaheadDistance
from shelf_env.privileged.planning import PlanningTeacher

#: A registered policy: ``factory(env, seed)`` -> an object with SB3's ``predict``.
PolicyFactory = Callable[[gym.Env, int], Any]


@dataclass(frozen=True)
class Wrapper:
    """A registered wrapper: ``wrap(agent, env, base)`` wraps the agent of policy ``base`` (its name or
    checkpoint path) acting in ``env``; ``check(base)`` raises a `ValueError` before any work starts
    where the wrapper cannot apply (None: it applies to every policy); ``files(base)`` lists the files
    beside the checkpoint that it reads (a learned model), which the evaluation fingerprints with it."""

    suffix: str
    wrap: Callable[[Any, gym.Env, str], Any]
    check: Callable[[str], None] | None = None
    files: Callable[[str], list[pathlib.Path]] | None = None


POLICIES: dict[str, PolicyFactory] = {}
WRAPPERS: dict[str, Wrapper] = {}
#: The heightmap cell size (m) of a registered policy that acts at its own (`register_policy`'s ``pixel_size``).
POLICY_PIXEL_SIZES: dict[str, float] = {}


def register_policy(name: str, factory: PolicyFactory, pixel_size: float | None = None) -> None:
    """Make ``name`` a policy (``factory(env, seed)``); a name is registered once. ``pixel_size``: the cell
    size (m) of the env it acts in (`policy_pixel_size`), e.g. to play a heuristic at the cells a learned
    wrapper reads; None: the env default (`shelf_env.params.PIXEL_SIZE`)."""
    if name in POLICIES:
        raise ValueError(f"policy {name!r} is already registered")
    if pixel_size is not None and not (isinstance(pixel_size, (int, float)) and 0 < pixel_size < 1):
        raise ValueError(f"policy {name!r}: pixel_size must be a cell size in metres in (0, 1), got {pixel_size!r}")
    POLICIES[name] = factory
    if pixel_size is not None:
        POLICY_PIXEL_SIZES[name] = float(pixel_size)


def register_wrapper(suffix: str, wrap: Callable[[Any, gym.Env, str], Any],
                     check: Callable[[str], None] | None = None,
                     files: Callable[[str], list[pathlib.Path]] | None = None) -> None:
    """Make ``<policy><suffix>`` play ``<policy>`` under ``wrap`` (see `Wrapper`); re-registering the same
    suffix replaces it (an experiment module imported twice)."""
    if not suffix.startswith("+") or len(suffix) < 2:
        raise ValueError(f"a wrapper suffix starts with '+', got {suffix!r}")
    WRAPPERS[suffix] = Wrapper(suffix, wrap, check, files)


def registering_modules() -> list[str]:
    """The modules outside this one that registered policies or wrappers (an experiment's): a worker
    process imports them (`import_modules`) so that it knows the same names as its parent."""
    found = [f.__module__ for f in POLICIES.values()] + [w.wrap.__module__ for w in WRAPPERS.values()]
    return sorted({m for m in found if m not in (__name__, "__main__", "__mp_main__")})


def import_modules(modules: list[str]) -> None:
    """Import ``modules`` (a worker's initializer: their registrations happen on import)."""
    import importlib

    for module in modules:
        importlib.import_module(module)


#: What a ``LABEL=`` prefix may be: it names files (cells, plots), so letters, digits, ``.``, ``_`` and ``-``.
LABEL_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


def split_label(policy: str) -> tuple[str | None, str]:
    """``policy``'s own label and the rest: ``"mine=runs/a/model.zip"`` -> ``("mine", "runs/a/model.zip")``;
    ``(None, policy)`` without one (an ``=`` after a path separator belongs to the path). A label that could not
    name a file is refused by name."""
    label, sep, rest = policy.partition("=")
    if not sep or "/" in label or os.sep in label:
        return None, policy
    if not LABEL_PATTERN.fullmatch(label) or not rest:
        raise ValueError(f"policy {policy!r}: LABEL=POLICY needs a label of letters, digits, '.', '_' and '-' "
                         f"and a policy after '=', got label {label!r}")
    return label, rest


def relabelled_file(policy: str, path: str | os.PathLike) -> str:
    """``policy`` with its checkpoint replaced by ``path``, keeping its label and wrappers (a copy of the file
    elsewhere, e.g. on a Ray worker, that must give the same records: without a label, the copy must keep the
    file's name)."""
    label, rest = split_label(policy)
    wrappers = _strip_wrappers(rest)[1]
    return f"{label + '=' if label else ''}{path}{''.join(wrappers)}"


def policy_wrappers(policy: str) -> tuple[str, tuple[str, ...]]:
    """``policy`` split into its base (a name or checkpoint path) and its wrappers, innermost first, without its
    label: ``"x=p.zip+fall-filter+loop-breaker"`` -> ``("p.zip", ("+fall-filter", "+loop-breaker"))``."""
    return _strip_wrappers(split_label(policy)[1])


def _strip_wrappers(policy: str) -> tuple[str, tuple[str, ...]]:
    """`policy_wrappers` of a policy whose label is already split off."""
    wrappers: list[str] = []
    stripped = True
    while stripped:
        stripped = False
        for suffix in WRAPPERS:
            if policy.endswith(suffix) and len(policy) > len(suffix):
                policy, wrappers, stripped = policy[:-len(suffix)], [suffix, *wrappers], True
    return policy, tuple(wrappers)


def policy_file(policy: str) -> str:
    """The checkpoint path (or the name) of ``policy``, without its wrappers."""
    return policy_wrappers(policy)[0]


def policy_files(policy: str) -> list[pathlib.Path]:
    """The files a policy reads: a checkpoint's (an ensemble's file, then its members; none for a name), then
    those of its wrappers (a learned model one reads, also under a name)."""
    name, wrappers = policy_wrappers(policy)
    own = [] if name in POLICIES else [pathlib.Path(name), *(ensemble_members(name) if is_ensemble(name) else [])]
    extra = [f for suffix in wrappers if WRAPPERS[suffix].files is not None
             for f in WRAPPERS[suffix].files(name)]  # type: ignore[misc]
    return [*own, *extra]


#: How the file of an output ensemble of checkpoints ends (`write_ensemble`, `ensemble_members`).
ENSEMBLE_SUFFIX = ".ensemble.json"


def is_ensemble(name: str | os.PathLike) -> bool:
    """Whether the policy file ``name`` is an ensemble's (ends with `ENSEMBLE_SUFFIX`)."""
    return str(name).endswith(ENSEMBLE_SUFFIX)


def ensemble_members(path: str | os.PathLike) -> list[pathlib.Path]:
    """The checkpoints the ensemble file ``path`` names, in order (relative paths are read from its folder).

    The file is JSON ``{"members": ["a.zip", "b.zip", ...]}`` with two or more members; a missing or malformed
    file, or a member that is not a file, is a `ValueError` naming it."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"ensemble {str(path)!r} is not a file")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"ensemble {path} is not readable JSON: {err}") from err
    members = data.get("members") if isinstance(data, dict) else None
    if not isinstance(members, list) or len(members) < 2 or not all(isinstance(m, str) and m for m in members):
        raise ValueError(f"ensemble {path} must hold {{\"members\": [two or more checkpoint paths]}}, got {data!r}")
    found = [path.parent / m for m in members]
    missing = [str(m) for m in found if not m.is_file()]
    if missing:
        raise ValueError(f"ensemble {path} names checkpoints that are not files: {missing}")
    return found


def write_ensemble(path: str | os.PathLike, members: list[str | os.PathLike]) -> pathlib.Path:
    """Write the ensemble file ``path`` (it must end with `ENSEMBLE_SUFFIX`) naming ``members`` (two or more
    existing checkpoints), each stored relative to its folder; atomically, so a bad call leaves nothing."""
    path = pathlib.Path(path)
    if not is_ensemble(path):
        raise ValueError(f"an ensemble file's name ends with {ENSEMBLE_SUFFIX!r}, got {str(path)!r}")
    if len(members) < 2:
        raise ValueError(f"an ensemble needs two or more members, got {len(members)}")
    missing = [str(m) for m in members if not pathlib.Path(m).is_file()]
    if missing:
        raise ValueError(f"ensemble members are not files: {missing}")
    folder = path.parent.resolve()
    relative = [os.path.relpath(pathlib.Path(m).resolve(), folder) for m in members]
    return write_json_atomically(path, {"members": relative})


def _members_agree(path: str | os.PathLike, read: Callable[[pathlib.Path], Any], what: str) -> Any:
    """``read`` of the members of the ensemble file ``path``: one value they share, or a `ValueError` naming ``what``
    differs between them."""
    found = {str(m): read(m) for m in ensemble_members(path)}
    if len(set(found.values())) > 1:
        raise ValueError(f"ensemble {path} mixes checkpoints of different {what}: {found}")
    return next(iter(found.values()))


def is_named(policy: str) -> bool:
    """Whether ``policy`` is a registered name (wrapped or not), not a checkpoint."""
    return policy_file(policy) in POLICIES


def policy_label(policy: str) -> str:
    """Short name used in files and plots: its ``LABEL=`` if it has one, else the name itself or a checkpoint's
    file stem; then its wrappers."""
    label, rest = split_label(policy)
    name, wrappers = _strip_wrappers(rest)
    if label is None and name in POLICIES:
        label = name
    elif label is None:
        label = pathlib.Path(name).name[:-len(ENSEMBLE_SUFFIX)] if is_ensemble(name) else pathlib.Path(name).stem
    return label + "".join(wrappers)


def checkpoint_primitives(path: str | os.PathLike) -> tuple[str, ...]:
    """The env primitives a PixelDoubleDQN checkpoint was trained with (from its map layout); of an ensemble,
    those its members share (members with different layouts are a `ValueError`)."""
    from stable_baselines3.common.save_util import load_from_zip_file

    if is_ensemble(path):
        return _members_agree(path, checkpoint_primitives, "primitives")
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"policy {str(path)!r} is neither one of {tuple(POLICIES)} nor an existing checkpoint file")
    try:
        data, _, _ = load_from_zip_file(path, load_data=True, device="cpu")
    except Exception as err:  # noqa: BLE001  (any failure to read is a bad checkpoint)
        raise ValueError(f"{path} is not a readable PixelDoubleDQN checkpoint: {err}") from err
    maps = (data or {}).get("policy_kwargs", {}).get("maps")
    names = {name for name, _ in maps} if maps else {"pick", "push"}
    return ("pick", "push") if "push" in names else ("pick",)


def checkpoint_pixel_size(path: str | os.PathLike) -> float:
    """The heightmap cell size (m) a PixelDoubleDQN checkpoint was trained at, from its observation width (an
    ensemble's: its members' one size; different sizes are a `ValueError`)."""
    from stable_baselines3.common.save_util import load_from_zip_file

    if is_ensemble(path):
        return _members_agree(path, checkpoint_pixel_size, "cell sizes")
    data, _, _ = load_from_zip_file(pathlib.Path(path), load_data=True, device="cpu")
    cols = int((data or {})["observation_space"].shape[2])
    return params.CABINET_WIDTH / cols


def policy_pixel_size(policy: str) -> float:
    """Cell size of the env a policy acts in: the checkpoint's; for a name, its registered one (`register_policy`)
    or the env default."""
    if is_named(policy):
        return POLICY_PIXEL_SIZES.get(policy_file(policy), params.PIXEL_SIZE)
    return checkpoint_pixel_size(policy_file(policy))


def check_policy(policy: str, primitives: tuple[str, ...] | None = None) -> tuple[str, ...]:
    """Validate a policy name (and a forced layout) before work starts; returns the env primitives."""
    name, wrappers = policy_wrappers(policy)
    for suffix in wrappers:
        check = WRAPPERS[suffix].check
        if check is not None:
            check(name)
    if is_named(policy):
        return primitives or ("pick", "push")
    needed = checkpoint_primitives(name)
    if primitives is not None and tuple(primitives) != needed:
        raise ValueError(
            f"checkpoint {policy} was trained with primitives {needed} but the evaluation env has {tuple(primitives)}"
        )
    return needed


def make_policy(policy: str, env: gym.Env, seed: int = 0) -> Any:
    """An object with SB3's ``predict`` for ``policy`` acting in ``env``, under its wrappers."""
    name, wrappers = policy_wrappers(policy)
    agent: Any
    if name in POLICIES:
        agent = POLICIES[name](env, seed)
    else:
        from sb3_pixeldqn import PixelDoubleDQN, QEnsemble

        if is_ensemble(name):
            agent = QEnsemble([PixelDoubleDQN.load(m, env=env, device="cpu") for m in ensemble_members(name)])
        else:
            agent = PixelDoubleDQN.load(name, env=env, device="cpu")
    for suffix in wrappers:
        agent = WRAPPERS[suffix].wrap(agent, env, name)
    return agent


def masked_greedy(model: Any, env: gym.Env, obs: Any) -> int:
    """``model``'s greedy action (SB3's ``predict``) within the env's current action masks."""
    masks = env.get_wrapper_attr("action_masks")()
    action, _ = model.predict(obs, deterministic=True, action_masks=masks)
    return int(np.asarray(action).reshape(-1)[0])


#: The loop breaker's suffix (`sb3_pixeldqn.LoopBreaker` with its defaults).
LOOP_BREAKER = "+loop-breaker"


def _check_geometry(base: str) -> None:
    if base in POLICIES:
        raise ValueError(f"{GEOMETRY_FILTER} filters a checkpoint's picks with the geometry risk saved beside it; "
                         f"{base!r} is not a checkpoint")
    if not geometry_risk_path(base).is_file():
        raise ValueError(f"policy {base}{GEOMETRY_FILTER}: no geometry risk model at {geometry_risk_path(base)} "
                         "(python -m research.fall_geometry export, in the repository, makes one)")


def _geometry_filtered(agent: Any, env: gym.Env, base: str) -> FallFilter:
    unwrapped: Any = env.unwrapped
    return FallFilter(agent, GeometryRisk.load(geometry_risk_path(base)), unwrapped.map_names, unwrapped.rows,
                      unwrapped.cols)


def _pick_guarded(agent: Any, env: gym.Env, base: str) -> PickGuard:
    unwrapped: Any = env.unwrapped
    return PickGuard(agent, tuple(unwrapped.map_names), unwrapped.rows, unwrapped.cols)


register_policy("h-d", lambda env, seed: DistanceHeuristic(env))
register_policy("h-a", lambda env, seed: AccessibilityHeuristic(env))
# privileged diagnostics (they read the simulator), not baselines: shelf_env.privileged.lookahead
register_policy("h-d-lookahead", lambda env, seed: LookaheadDistance(env))
register_policy("h-a-lookahead", lambda env, seed: LookaheadAccessibility(env))
register_policy("h-d-planner", lambda env, seed: PlanningTeacher(env))
register_policy("random", lambda env, seed: RandomPolicy(env, seed=seed))
register_wrapper(LOOP_BREAKER, lambda agent, env, base: LoopBreaker(agent))
# a camera-only pick filter (shelf_env.fall_filter): the shipped P+S plays under it, then the loop breaker
register_wrapper(GEOMETRY_FILTER, _geometry_filtered, check=_check_geometry,
                 files=lambda base: [geometry_risk_path(base)])
# a camera-only guard against wasted picks (shelf_env.pick_guard): the shipped P+S plays under it after the filter
register_wrapper(PICK_GUARD, _pick_guarded)
