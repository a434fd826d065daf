"""A camera-only guard against wasted pushes: ``<policy>+push-guard`` and ``<policy>+pick-first``.

In series 5 of the teacher dataset (driven by the shipped P+S as it plays) about half of the policy's greedy actions
are pushes, most of them pushes of objects that already look sorted, and they sort almost nothing
(docs/experiments/push-guard.md). `PushGuard` masks, before the policy chooses,

- ``mode="sorted"`` (``+push-guard``): the pushes whose blade meets a cell of an object that looks sorted within
  the push's length (the env's mask geometry, `shelf_env.actions.occupancy_masks`, on the sorted-looking cells:
  `ObservationView.sorted_cells`, as the heuristics and the pick guard read them);
- ``mode="all"`` (``+pick-first``): every push while any pick is allowed.

Where that would leave nothing allowed it stands aside. Put innermost (``p_s.zip+push-guard+geometry-filter+...``)
it sees the masks left by the filter, the pick guard and the loop breaker, so it never trades a push for a pick the
filter masked. It reads the observation and the masks only and is not learned. Counters: ``guarded`` (decisions
where it masked at least one allowed push) and ``unguarded`` (decisions where it stood aside).

    python -m research.evaluate --policies "p_s.zip+push-guard+geometry-filter+pick-guard+loop-breaker" ...
    python -m research.push_guard stats data/teacher --series s05 --out results/push_guard/series5.md
    python -m research.push_guard falls "p_s.zip+push-guard+..." --ns 8 --runs 30 --seed 0 --out falls30.json

``stats`` reads the series' labels of the driver's greedy action (source ``greedy``): how often it is a push or a
pick, what each did (sorted, unsorted, fell), and the same split for the pushes this guard would mask.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Any

import gymnasium as gym
import numpy as np

from research import table_command
from shelf_env import params
from shelf_env.actions import occupancy_masks
from shelf_env.baselines.heuristics import ObservationView
from shelf_env.fall_filter import PickMask
from shelf_env.policies import register_wrapper
from shelf_env.privileged import dataset

#: The wrappers' suffixes and the modes they play.
MODES = {"+push-guard": "sorted", "+pick-first": "all"}


def sorted_pushes(obs: np.ndarray, map_names: tuple[str, ...]) -> np.ndarray:
    """Flat bool over the actions of ``map_names`` on ``obs``'s grid: the pushes whose blade meets a cell of an object
    that looks sorted within the push's length (never a pick)."""
    rows = obs.shape[1]
    cells = ObservationView.from_observation(obs, margin_cells=0).sorted_cells
    if not cells.any():  # occupancy_masks allows everything where nothing is occupied
        return np.zeros(len(map_names) * cells.size, bool)
    out = occupancy_masks(cells, params.CABINET_DEPTH / rows, map_names).reshape(len(map_names), -1)
    out[list(map_names).index("pick")] = False
    return out.reshape(-1)


class PushGuard(PickMask):
    """Wrap ``policy`` (SB3's ``predict`` with ``action_masks``): the pushes at sorted-looking objects
    (``mode="sorted"``), or every push while a pick is allowed (``mode="all"``), are masked out before it chooses
    (module docstring)."""

    STATS = ("guarded", "unguarded")

    def __init__(self, policy: Any, map_names: tuple[str, ...], rows: int, cols: int, mode: str = "sorted") -> None:
        super().__init__(policy, map_names, rows, cols)
        if mode not in MODES.values():
            raise ValueError(f"mode must be one of {sorted(MODES.values())}, got {mode!r}")
        if len(map_names) < 2:
            raise ValueError(f"PushGuard needs push maps besides the pick map; the policy's maps are {map_names}")
        self.mode, self.map_names = mode, tuple(map_names)

    def banned(self, obs: np.ndarray, allowed: np.ndarray) -> np.ndarray:
        """Flat bool over the actions: the pushes this guard masks in ``obs`` given the caller's ``allowed``."""
        if self.mode == "sorted":
            return sorted_pushes(obs, self.map_names)
        out = np.zeros((self.n_maps, self.rows * self.cols), bool)
        if allowed.reshape(self.n_maps, -1)[self.pick].any():  # every push map
            out[:] = True
            out[self.pick] = False
        return out.reshape(-1)

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        obs, allowed = self.observation(observation), self.allowed(action_masks)
        return self.choose_actions(obs, allowed, self.banned(obs, allowed), state, deterministic)


def _wrapper(mode: str) -> Any:
    def wrap(agent: Any, env: gym.Env, base: str) -> PushGuard:
        unwrapped: Any = env.unwrapped
        return PushGuard(agent, tuple(unwrapped.map_names), unwrapped.rows, unwrapped.cols, mode)
    return wrap


for _suffix, _mode in MODES.items():
    register_wrapper(_suffix, _wrapper(_mode))


def greedy_stats(folder: pathlib.Path, series: str) -> dict[str, int]:
    """Counts over the shards of ``series`` in ``folder``: the driver's greedy actions by primitive and outcome, the
    pushes that `PushGuard` (mode ``sorted``) would mask, and the push states with a labelled sorting pick."""
    greedy = dataset.SOURCES.index("greedy")
    counts: dict[str, int] = {}

    def add(key: str, value: Any = 1) -> None:
        counts[key] = counts.get(key, 0) + int(value)

    paths = [p for p in dataset.shard_files(folder) if p.name.startswith(f"{series}_")]
    if not paths:
        raise ValueError(f"no shards of series {series!r} in {folder}")
    for path in paths:
        shard = dataset.load_shard(path)
        a, names = shard.arrays, tuple(shard.meta["layout"]["map_names"])
        rows, cols = a["obs"].shape[2:]
        pick = names.index("pick")
        cell_map = a["label_action"] // (rows * cols)
        for s in np.unique(a["label_state"][a["label_source"] == greedy]):
            here = a["label_state"] == s
            i = int(np.flatnonzero(here & (a["label_source"] == greedy))[0])
            valid, dsorted = bool(a["label_valid"][i]), int(a["label_dsorted"][i])
            kind = "pick" if cell_map[i] == pick else "push"
            outcome = {"": 1, "_sorted": valid and dsorted > 0, "_unsorted": valid and dsorted < 0,
                       "_fell": a["label_fell"][i]}
            for suffix, value in outcome.items():
                add(kind + suffix, value)
            if kind == "pick":
                continue
            good_pick = here & (cell_map == pick) & a["label_valid"] & (a["label_dsorted"] > 0)
            add("push_state_good_pick", good_pick.any())
            teacher = int(a["teacher_action"][s])
            add("push_state_good_pick_teacher_picks", good_pick.any() and teacher >= 0
                and teacher // (rows * cols) == pick)
            masked = "guarded" if sorted_pushes(a["obs"][s], names)[a["label_action"][i]] else "free"
            for suffix, value in outcome.items():
                add(f"push_{masked}{suffix}", value)
    return counts


def stats_table(counts: dict[str, int], series: str) -> str:
    """``greedy_stats`` as markdown."""
    def pct(key: str, of: str) -> str:
        return f"{100 * counts.get(key, 0) / counts[of]:.1f} %" if counts.get(of) else "-"

    states = counts.get("pick", 0) + counts.get("push", 0)
    lines = [f"The driver's greedy actions in series {series}: {states} states (`python -m research.push_guard "
             f"stats`).", "", "| greedy action | actions | share | sorts an object | unsorts one | drops one |",
             "|---|---|---|---|---|---|"]
    for kind, label in (("pick", "pick"), ("push", "push"), ("push_guarded", "push at a sorted-looking object"),
                        ("push_free", "any other push")):
        lines.append(f"| {label} | {counts.get(kind, 0)} | {100 * counts.get(kind, 0) / states:.1f} % | "
                     f"{pct(kind + '_sorted', kind)} | {pct(kind + '_unsorted', kind)} | {pct(kind + '_fell', kind)} |")
    lines += ["", f"Push states with a labelled pick that kept the scene valid and sorted an object: "
              f"{counts.get('push_state_good_pick', 0)} ({pct('push_state_good_pick', 'push')}); the teacher "
              f"picked at {pct('push_state_good_pick_teacher_picks', 'push_state_good_pick')} of them."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    stats = sub.add_parser("stats", help="what the driver's greedy pushes did in one series of the dataset")
    stats.add_argument("data", type=pathlib.Path, help="the dataset folder")
    stats.add_argument("--series", default="s05", help="the series' prefix (default s05)")
    stats.add_argument("--out", type=pathlib.Path, help="write the table here (else print it)")
    sub.add_parser("falls", help="python -m shelf_env.evaluation.falls with +push-guard and +pick-first registered "
                   "(its arguments follow)", add_help=False)
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["falls"]:
        from shelf_env.evaluation import falls

        return falls.main(argv[1:])
    args = parser.parse_args(argv)
    return table_command(lambda: stats_table(greedy_stats(args.data, args.series), args.series), args.out)


if __name__ == "__main__":
    raise SystemExit(main())
