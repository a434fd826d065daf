"""The evaluation protocol of §V: SR, AE and mAE per number of objects N, over runs and seeds.

A *cell* is one (policy, object set, N, seed) with ``runs`` episodes. Episode ``run`` of seed
``seed`` at N objects always starts from the scene of `scene_seed(seed, N, run)`, whatever the
policy or action layout, so every policy is compared on identical initial arrangements.

Per seed: SR = % of runs sorted in fewer than ``max_actions`` (40) actions; over successful runs
only, AE = N / actions and mAE = (objects unsorted at the start) / actions. Per N: mean and
standard deviation of the per-seed values over seeds (Fig. 10).

Policies are named by a string and built by the registry (`shelf_env.policies`): ``"h-d"``,
``"h-a"``, ``"random"``, the privileged ``"h-d-lookahead"`` / ``"h-a-lookahead"``, or a `PixelDoubleDQN`
zip, with registered wrappers appended (``"examples/pretrained/p_s.zip+loop-breaker"``).
"""

from __future__ import annotations

import csv
import functools
import hashlib
import json
import math
import pathlib
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pixeldqn.buffers import unchanged
from sb3_pixeldqn.loop_breaker import predict_takes
from shelf_env import params
from shelf_env.files import write_atomically, write_json_atomically
from shelf_env.policies import (  # noqa: F401  (re-exported: the evaluation's names for policies)
    LOOP_BREAKER,
    check_policy,
    checkpoint_pixel_size,
    checkpoint_primitives,
    is_named,
    make_policy,
    policy_file,
    policy_files,
    policy_label,
    policy_pixel_size,
    policy_wrappers,
)

#: Evaluation seed of the held-out scenes behind learning claims (docs/experiments/learning-recipe.md): no training
#: run, greedy curriculum check or tuning probe draws scenes from it.
HELDOUT_SEED = 1000


@dataclass(frozen=True)
class EpisodeRecord:
    """What one evaluation episode produced."""

    policy: str
    object_set: str
    num_objects: int
    seed: int
    run: int
    success: bool
    actions: int
    num_unsorted_initial: int
    fell: bool
    noops: int = 0  # actions that left the observation unchanged
    #: Why an unsuccessful episode failed (`FAILURES`), "" when it succeeded (or for cells written
    #: before this field existed).
    failure: str = ""
    max_repeat: int = 0  # longest run of one action repeated back to back
    #: The episode's share of the policy's counters (`policy_counters`: its own ``stats`` dict of ints, such as the
    #: lookahead's vetoes and unavoidable steps, `shelf_env.privileged.lookahead.STAT_KEYS`, and those of the
    #: policies it wraps as ``<wrapper>.<counter>``); empty for a policy without any.
    policy_stats: dict[str, int] = field(default_factory=dict)
    #: The machine that played the episode (`machine_label`), "" for cells written before this
    #: field existed. Episodes are bit-identical on one machine, not across machines.
    machine: str = ""


#: Failure categories of `classify_failure`, from the episode's trace.
FAILURES = ("fell", "unstable", "wrong_class", "loop", "timeout")
#: A time-out is a loop when at least this share of its actions left the observation unchanged,
#: or one action was repeated back to back at least ``LOOP_REPEAT`` times.
LOOP_NOOP_SHARE = 0.5
LOOP_REPEAT = 5


def classify_failure(success: bool, fell: bool, terminated: bool, actions: int, noops: int, max_repeat: int,
                     all_in_regions: bool) -> str:
    """Why an episode failed, from its trace ("" if it succeeded):

    - ``fell``: an object left the cabinet (the env's drag failure, §V-d);
    - ``unstable``: the episode ended invalid without a fall (an object not at rest);
    - ``wrong_class``: it ran out of actions with every object in some region, not all in their own;
    - ``loop``: it ran out of actions repeating itself (`LOOP_NOOP_SHARE`, `LOOP_REPEAT`);
    - ``timeout``: it ran out of actions otherwise.
    """
    if success:
        return ""
    if fell:
        return "fell"
    if terminated:
        return "unstable"
    if all_in_regions:
        return "wrong_class"
    if noops >= LOOP_NOOP_SHARE * max(actions, 1) or max_repeat >= LOOP_REPEAT:
        return "loop"
    return "timeout"


def scene_seed(seed: int, num_objects: int, run: int) -> int:
    """Reset seed of run ``run`` at N = ``num_objects`` for evaluation seed ``seed`` (policy-independent)."""
    return int(np.random.SeedSequence([seed, num_objects, run]).generate_state(1)[0])


def check_ns(ns: list[int], max_objects: int = params.MAX_OBJECTS) -> list[int]:
    bad = [n for n in ns if not 1 <= n <= max_objects]
    if bad:
        raise ValueError(f"N must be in 1..{max_objects} for ShelfSort-v0; got {bad}")
    return sorted(set(int(n) for n in ns))


def takes_action_masks(policy: Any) -> bool:
    """Whether ``policy`` acts with sb3-contrib's ``action_masks=``: its ``predict`` accepts them (a
    PixelDoubleDQN does) and it ``acts_masked`` (False for a model trained with ``masked=False``,
    which keeps the paper's all-pixel argmax at evaluation)."""
    return bool(getattr(policy, "acts_masked", True)) and predict_takes(policy, "action_masks")


def greedy_action(env: gym.Env, policy: Any, obs: Any, first: bool, masked: bool, starts: bool) -> int:
    """``policy``'s greedy action in ``obs`` as an evaluation asks for it: with the env's masks when
    it acts masked (`takes_action_masks`), with SB3's ``episode_start`` (``first``) when its
    ``predict`` takes it (``starts``)."""
    kwargs: dict[str, Any] = {"action_masks": env.get_wrapper_attr("action_masks")()} if masked else {}
    if starts:
        kwargs["episode_start"] = np.array([first])
    action, _ = policy.predict(obs, deterministic=True, **kwargs)
    return int(np.asarray(action).reshape(-1)[0])


def policy_counters(policy: Any) -> dict[str, int]:
    """The counters of ``policy`` and of every test-time wrapper under it: the ``stats`` dict of ints of each layer
    down its ``.policy`` chain (`shelf_env.fall_filter.FallFilter`, `shelf_env.pick_guard.PickGuard`,
    `sb3_pixeldqn.LoopBreaker`, ...). The outermost layer's counters keep their names; a wrapped layer's are named
    ``<layer's class in snake case>.<counter>`` (``fall_filter.masked``), since two layers may count under one name
    (the filter and the guard both count ``masked``)."""
    counters: dict[str, int] = {}
    layer, seen = policy, set()
    while layer is not None and id(layer) not in seen:
        seen.add(id(layer))
        stats = getattr(layer, "stats", None)
        if isinstance(stats, dict):
            prefix = "" if layer is policy else snake_case(type(layer).__name__) + "."
            counters.update({prefix + str(key): int(value) for key, value in stats.items()})
        layer = getattr(layer, "policy", None)
    return counters


def snake_case(name: str) -> str:
    """``FallFilter`` -> ``fall_filter``."""
    return "".join("_" + c.lower() if c.isupper() and i else c.lower() for i, c in enumerate(name))


def run_episode(env: gym.Env, policy: Any, reset_seed: int, max_actions: int = params.MAX_ACTIONS) -> dict:
    """Roll out ``policy`` greedily from the scene of ``reset_seed``; success needs < ``max_actions`` actions.

    A policy whose ``predict`` takes ``action_masks`` gets the env's masks at every step, as a
    MaskablePPO evaluation does, unless it was trained with ``masked=False``; the heuristics choose
    among object cells by construction. A policy whose ``predict`` takes SB3's ``episode_start``
    gets it (True at the first step): a policy with memory (a `LoopBreaker`) forgets the last
    episode there. The episode's increments of the policy's counters (`policy_counters`: its own and its wrapped
    layers') are recorded (``policy_stats``).
    """
    stats_before = policy_counters(policy)
    obs, info = env.reset(seed=reset_seed)
    unsorted = info["num_unsorted_initial"]
    masked, starts = takes_action_masks(policy), predict_takes(policy, "episode_start")
    noops, repeat, max_repeat, last = 0, 0, 0, None
    while True:
        action = greedy_action(env, policy, obs, last is None, masked, starts)
        next_obs, _, terminated, truncated, info = env.step(action)
        noops += unchanged(obs, next_obs)
        repeat = repeat + 1 if action == last else 1
        max_repeat, last = max(max_repeat, repeat), action
        obs = next_obs
        if terminated or truncated:
            break
    actions = int(info["action_count"])
    success = bool(info["is_success"]) and actions < max_actions
    failure = classify_failure(success, bool(info["fell"]), bool(terminated), actions, noops, max_repeat,
                               "relabelled" in info)
    stats = policy_counters(policy)
    return {"success": success, "actions": actions, "num_unsorted_initial": int(unsorted), "fell": bool(info["fell"]),
            "noops": noops, "failure": failure, "max_repeat": max_repeat,
            "policy_stats": {key: value - stats_before.get(key, 0) for key, value in stats.items()}}


#: Env options an evaluation may set (the rest of the env is fixed by the protocol and the policy).
CONDITION_KEYS = ("perception_noise", "closed_loop", "physics", "safe_picks")


def check_conditions(conditions: dict[str, Any] | None) -> dict[str, Any]:
    """Validate evaluation conditions (env options, `CONDITION_KEYS`) by building them; returns a copy."""
    conditions = dict(conditions or {})
    unknown = sorted(set(conditions) - set(CONDITION_KEYS))
    if unknown:
        raise ValueError(f"unknown evaluation conditions {unknown}; known: {list(CONDITION_KEYS)}")
    from shelf_env.conditions.perception_noise import PerceptionNoise

    PerceptionNoise.from_any(conditions.get("perception_noise"))
    if not isinstance(conditions.get("safe_picks", False), bool):
        raise ValueError(f"safe_picks must be true or false, got {conditions['safe_picks']!r}")
    if "closed_loop" in conditions:
        from shelf_env.conditions.closed_loop import DragWatch

        if not isinstance(conditions["closed_loop"], (bool, dict)):  # JSON: no DragWatch objects
            raise ValueError(f"closed_loop must be true, false or a dict of DragWatch fields, "
                             f"got {conditions['closed_loop']!r}")
        DragWatch.from_any(conditions["closed_loop"])
    if "physics" in conditions:
        from shelf_env.world.cabinet import PHYSICS, Physics

        if not isinstance(conditions["physics"], str):
            raise ValueError(f"physics must be one of {sorted(PHYSICS)}, got {conditions['physics']!r}")
        Physics.named(conditions["physics"])
    return conditions


def folder_conditions(out: pathlib.Path) -> dict[str, Any]:
    """The conditions an evaluation folder's cells were made under (its ``conditions.json``; none
    when it has no such file)."""
    path = pathlib.Path(out) / "conditions.json"
    return check_conditions(json.loads(path.read_text())) if path.exists() else {}


def make_env(policy: str, num_objects: int, object_set: str = "ycb", primitives: tuple[str, ...] | None = None,
             conditions: dict[str, Any] | None = None) -> gym.Env:
    """The env an evaluation cell of ``policy`` runs in (its layout and cell size, the protocol's
    action limit, ``conditions``)."""
    return gym.make("ShelfSort-v0", num_objects=num_objects, object_set=object_set,
                    primitives=check_policy(policy, primitives), max_actions=params.MAX_ACTIONS,
                    pixel_size=policy_pixel_size(policy), **check_conditions(conditions))


@functools.lru_cache(maxsize=1)
def machine_label() -> str:
    """This machine as evaluation records name it: CPU model, architecture, OS, and the versions of
    PyBullet and NumPy. PyBullet's floating point differs between CPUs, so one scene can end
    differently on two machines (on two machines, 5 of H-d's 30 episodes at N = 8, seed 0, did)."""
    import platform
    from importlib.metadata import version

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), cpu)
    except OSError:
        pass
    return f"{cpu} ({platform.machine()}, {platform.system()}), pybullet {version('pybullet')}, numpy {np.__version__}"


def machines(records: list[EpisodeRecord]) -> dict[str, int]:
    """Episodes per machine that played them (`EpisodeRecord.machine`; "unrecorded" for old cells)."""
    return dict(sorted(Counter(r.machine or "unrecorded" for r in records).items()))


def evaluate_cell(policy: str, num_objects: int, seed: int, runs: int, object_set: str = "ycb",
                  primitives: tuple[str, ...] | None = None,
                  conditions: dict[str, Any] | None = None) -> list[EpisodeRecord]:
    """All ``runs`` episodes of one (policy, N, seed) cell, under ``conditions`` (env options such
    as perception noise or the closed loop; `CONDITION_KEYS`)."""
    env = make_env(policy, num_objects, object_set, primitives, conditions)
    try:
        agent = make_policy(policy, env, seed=scene_seed(seed, num_objects, 10**6))  # its own stream
        return [
            EpisodeRecord(policy_label(policy), object_set, num_objects, seed, run,
                          **run_episode(env, agent, scene_seed(seed, num_objects, run)), machine=machine_label())
            for run in range(runs)
        ]
    finally:
        env.close()


# ---------------------------------------------------------------- metrics
def episode_summary(records: list[EpisodeRecord]) -> dict[str, Any]:
    """Sorted count, SR (%), mean actions per success, share of unchanged-observation actions, falls,
    and the count of each failure category (`FAILURES`)."""
    ok = [r for r in records if r.success]
    actions = sum(r.actions for r in records)
    return {
        "scenes": len(records), "sorted": len(ok), "sr": 100.0 * len(ok) / len(records) if records else math.nan,
        "actions_per_success": float(np.mean([r.actions for r in ok])) if ok else math.nan,
        "noop_share": sum(r.noops for r in records) / max(1, actions),
        "fell": sum(r.fell for r in records),
        "failures": {kind: sum(r.failure == kind for r in records) for kind in FAILURES},
    }


def seed_metrics(records: list[EpisodeRecord]) -> dict[str, float]:
    """SR (%), AE and mAE of one seed's runs (AE, mAE over successful runs; nan if none)."""
    ok = [r for r in records if r.success]
    sr = 100.0 * len(ok) / len(records) if records else math.nan
    ae = float(np.mean([r.num_objects / r.actions for r in ok])) if ok else math.nan
    mae = float(np.mean([r.num_unsorted_initial / r.actions for r in ok])) if ok else math.nan
    return {"sr": sr, "ae": ae, "mae": mae}


def summarize(records: list[EpisodeRecord]) -> list[dict[str, Any]]:
    """One row per (policy, object set, N): mean and std over seeds of SR, AE, mAE, and counts."""
    groups: dict[tuple, dict[int, list[EpisodeRecord]]] = {}
    for r in records:
        groups.setdefault((r.policy, r.object_set, r.num_objects), {}).setdefault(r.seed, []).append(r)
    rows = []
    for (policy, object_set, n), by_seed in sorted(groups.items()):
        per_seed = [seed_metrics(rs) for _, rs in sorted(by_seed.items())]
        row: dict[str, Any] = {"policy": policy, "object_set": object_set, "num_objects": n,
                               "seeds": len(per_seed), "runs": sum(len(rs) for rs in by_seed.values())}
        for key in ("sr", "ae", "mae"):
            values = np.array([m[key] for m in per_seed], dtype=float)
            finite = values[np.isfinite(values)]
            row[f"{key}_mean"] = float(finite.mean()) if finite.size else math.nan
            row[f"{key}_std"] = float(finite.std()) if finite.size else math.nan
        everything = [r for rs in by_seed.values() for r in rs]
        summary = episode_summary(everything)
        row["fell_rate"] = summary["fell"] / len(everything)
        for kind in FAILURES[1:]:  # shares of all episodes; cells from before `failure` existed count none
            row[f"{kind}_rate"] = summary["failures"][kind] / len(everything)
        row["noop_share"] = summary["noop_share"]
        rows.append(row)
    return rows


# ---------------------------------------------------------------- paired comparisons
#: Episodes by (policy, N) and then by scene (seed, run): what a comparison on the same scenes reads.
SceneIndex = dict[tuple[str, int], dict[tuple[int, int], EpisodeRecord]]


def by_scene(records: list[EpisodeRecord]) -> SceneIndex:
    """Every episode of ``records`` by (policy, N) and then by its scene (seed, run); of two records of one
    episode the later one is kept (the order in which folders were read)."""
    index: SceneIndex = {}
    for r in records:
        index.setdefault((r.policy, r.num_objects), {})[(r.seed, r.run)] = r
    return index


def scene_episodes(index: SceneIndex, policy: str, n: int,
                   scenes: list[tuple[int, int]]) -> list[EpisodeRecord] | None:
    """``policy``'s episodes on exactly ``scenes`` at N = ``n``, in their order; None where it lacks one of them
    (or ``scenes`` is empty): a count over other scenes would not be paired."""
    played = index.get((policy, n), {})
    found = [played.get(scene) for scene in scenes]
    return [r for r in found if r is not None] if found and None not in found else None


def paired_sr(index: SceneIndex, policy: str, n: int, scenes: list[tuple[int, int]]) -> float | None:
    """``policy``'s SR (%) over exactly ``scenes`` at N = ``n``; None where it lacks one of them."""
    done = scene_episodes(index, policy, n, scenes)
    return None if done is None else 100.0 * sum(r.success for r in done) / len(done)


def common_scenes(index: SceneIndex, policies: list[str], n: int) -> list[tuple[int, int]]:
    """The scenes (seed, run) at N = ``n`` that every one of ``policies`` played, sorted."""
    sets = [set(index.get((p, n), {})) for p in policies]
    return sorted(set.intersection(*sets)) if sets else []


def margin_over_best(index: SceneIndex, policy: str, n: int, scenes: list[tuple[int, int]],
                     rivals: list[str]) -> dict[str, float] | None:
    """``policy``'s SR on ``scenes`` at N = ``n`` (``sr``), the best of ``rivals``' SRs on exactly those scenes
    (``best``) and the difference (``margin``, SR points): how the paper's §V compares a learned policy with the
    better heuristic. None where ``policy`` or a rival lacks one of the scenes, or ``rivals`` is empty."""
    mine = paired_sr(index, policy, n, scenes)
    theirs = [paired_sr(index, rival, n, scenes) for rival in rivals]
    if mine is None or not theirs or any(t is None for t in theirs):
        return None
    best = max(t for t in theirs if t is not None)
    return {"sr": mine, "best": best, "margin": mine - best}


# ---------------------------------------------------------------- files
def cell_path(out: pathlib.Path, policy: str, object_set: str, n: int, seed: int, runs: int) -> pathlib.Path:
    return out / "cells" / f"{policy_label(policy)}__{object_set}__N{n:02d}__seed{seed}__runs{runs}.json"


def save_cell(path: pathlib.Path, records: list[EpisodeRecord]) -> None:
    write_json_atomically(path, [asdict(r) for r in records])


def load_cell(path: pathlib.Path) -> list[EpisodeRecord]:
    return [EpisodeRecord(**r) for r in json.loads(path.read_text())]


def load_cells(out: pathlib.Path) -> list[EpisodeRecord]:
    """Every record of every cell in ``<out>/cells/``; `ValueError` if there is none."""
    paths = sorted((out / "cells").glob("*.json"))
    if not paths:
        raise ValueError(f"{out}/cells has no evaluation cells")
    return [r for path in paths for r in load_cell(path)]


def fingerprint_path(out: pathlib.Path, policy: str) -> pathlib.Path:
    """Where ``<out>`` records which checkpoint file its cells of ``policy``'s label came from."""
    return out / "cells" / f"{policy_label(policy)}.sha256"


def policy_digest(policy: str) -> str:
    """The sha256 of the files a policy reads (`shelf_env.policies.policy_files`: the checkpoint and its
    wrappers' own files, their bytes together); "" for a registered name whose wrappers read none."""
    files = policy_files(policy)
    return hashlib.sha256(b"".join(f.read_bytes() for f in files)).hexdigest() if files else ""


def check_cell_owner(out: pathlib.Path, policies: list[str], record: bool = False) -> None:
    """Cells are keyed by the policy's label (`policy_label`: a checkpoint's file stem unless it is given
    ``LABEL=``); make sure a label stands for one policy and one file. Two policies with one label in
    ``policies`` are refused, and so is a checkpoint whose label's cells in ``<out>`` came from another file
    (a retrained model shipped under the same name): its old cells would otherwise be reused as its results.
    ``record=True`` writes each checkpoint's sha256 beside its cells (before the first cell is written; with a
    wrapper that reads a file of its own, `shelf_env.policies.policy_files`, of all their bytes together)."""
    seen: dict[str, str] = {}
    for policy in policies:
        label = policy_label(policy)
        if seen.setdefault(label, policy) != policy:
            raise ValueError(f"policies {seen[label]} and {policy} share the label {label!r} that names their "
                             "cells: give one another label (LABEL=PATH) or rename its file")
        if not policy_files(policy):  # a name whose wrappers read no file of their own
            continue
        digest = policy_digest(policy)
        path = fingerprint_path(out, policy)
        if path.exists():
            before = path.read_text().strip()
            if before != digest:
                raise ValueError(f"{out} holds cells of another {label!r} checkpoint (sha256 {before[:12]}; "
                                 f"{policy} is {digest[:12]}): use another --out or another label (LABEL=PATH), "
                                 f"or delete {out / 'cells'}/{label}__* and {path.name} to evaluate it afresh")
        elif record:
            write_atomically(path, functools.partial(pathlib.Path.write_text, data=digest + "\n"))


def cached_cell(out: pathlib.Path, policy: str, num_objects: int, seed: int, runs: int,
                object_set: str) -> list[EpisodeRecord]:
    """One cell's records from ``<out>/cells/`` if it is there, else evaluated and written there."""
    check_cell_owner(out, [policy], record=True)
    path = cell_path(out, policy, object_set, num_objects, seed, runs)
    if path.exists():
        return load_cell(path)
    records = evaluate_cell(policy, num_objects, seed, runs, object_set)
    save_cell(path, records)
    return records


def write_results(out: pathlib.Path, records: list[EpisodeRecord], config: dict[str, Any]) -> list[dict[str, Any]]:
    """``results.csv`` (the summary) and ``results.json`` (configuration, summary, per-seed metrics)."""
    rows = summarize(records)
    out.mkdir(parents=True, exist_ok=True)

    def write_csv(tmp: pathlib.Path) -> None:
        with open(tmp, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            for row in rows:
                writer.writerow({k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()})

    write_atomically(out / "results.csv", write_csv)
    per_seed: dict[str, list[EpisodeRecord]] = {}
    for r in records:
        per_seed.setdefault(f"{r.policy}|{r.object_set}|{r.num_objects}|{r.seed}", []).append(r)
    write_json_atomically(out / "results.json", {
        "config": config,
        "machines": machines(records),
        "summary": rows,
        "per_seed": {k: seed_metrics(v) for k, v in sorted(per_seed.items())},
    })
    return rows


# ---------------------------------------------------------------- plots
def plot_metrics(rows: list[dict[str, Any]], png: pathlib.Path, object_set: str | None = None,
                 title: str = "") -> list[str]:
    """Fig. 10: SR, AE, mAE against N, one line per policy with a ±1 std band over seeds.

    With ``object_set=None`` and rows for several object sets, lines are per (policy, set) — Fig. 12.
    Returns the line labels, in legend order.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sel = [r for r in rows if object_set is None or r["object_set"] == object_set]
    sets = sorted({r["object_set"] for r in sel})
    labels: list[str] = []
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for policy in sorted({r["policy"] for r in sel}):
        for oset in sets:
            line = sorted((r for r in sel if r["policy"] == policy and r["object_set"] == oset),
                          key=lambda r: r["num_objects"])
            if not line:
                continue
            label = policy if len(sets) == 1 else f"{policy} ({oset})"
            labels.append(label)
            ns = np.array([r["num_objects"] for r in line])
            for ax, key, name in zip(axes, ("sr", "ae", "mae"), ("SR (%)", "AE", "mAE")):
                mean = np.array([r[f"{key}_mean"] for r in line], dtype=float)
                std = np.array([r[f"{key}_std"] for r in line], dtype=float)
                (handle,) = ax.plot(ns, mean, marker="o", ms=3, label=label)
                ax.fill_between(ns, mean - std, mean + std, color=handle.get_color(), alpha=0.2)
                ax.set_xlabel("number of objects N")
                ax.set_ylabel(name)
    axes[0].set_ylim(-2, 102)
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    write_atomically(png, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return labels
