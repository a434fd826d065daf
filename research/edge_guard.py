"""Objects at a region's edge last: ``<policy>+edge-guard`` (docs/experiments/edge-guard.md).

The pick guard (`shelf_env.pick_guard`) skips objects that look sorted: a visible blob whose centroid lies in its
class's region as the region's tint shows it (`ObservationView.sorted_cells`). Two kinds of sorted objects escape
that reading and get picked and put back: those at the region's edge (the blob's centroid a cell outside the tint,
the object's base inside), and those in a region whose edge columns objects hide (the visible tint is narrower than
the region, which is always ``REGION_WIDTH`` wide). `borderline_cells` reads both: an object that does not look
sorted but whose centroid lies within its region with the columns completed to the region's width on either side
(half a cell of slack) and one cell of slack in depth. `EdgeGuard` masks the borderline objects' pick cells while
the caller leaves an allowed pick on some other object, and stands aside otherwise, so that a borderline object that
is really unsorted is picked once the clear ones are done. Pushes are never masked. It reads the observation and the
masks only and is not learned. Counters: ``deferred`` (decisions where it masked at least one allowed borderline
pick) and ``released`` (decisions where only borderline picks were left).

    python -m research.evaluate --policies "p_s.zip+edge-guard+geometry-filter+pick-guard+loop-breaker" ...
    python -m research.edge_guard stats data/teacher --max-shards s05:200 --out results/edge_guard/series5.md
    python -m research.edge_guard live --n 8 --runs 20 --first-seed 7000 --out results/edge_guard/live.md

``stats`` reads a series' greedy picks (the driver's own choices) by outcome and by the two readings; ``live``
plays a policy on training-seed scenes and says, per pick, whether the object it took was sorted before and after
by the env's rule (`shelf_env.world.task.judge`) and whether it looked sorted or borderline.
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
from shelf_env.baselines.heuristics import ObservationView
from shelf_env.fall_filter import PickMask
from shelf_env.policies import register_wrapper

#: The suffix: ``<checkpoint>+edge-guard+geometry-filter+pick-guard+loop-breaker``.
EDGE_GUARD = "+edge-guard"
#: Slack around the read region, in cells: rows (depth, which is drawn per scene) and columns (whose width is known).
ROW_SLACK, COL_SLACK = 1.0, 0.5


def borderline_cells(obs: np.ndarray, row_slack: float = ROW_SLACK, col_slack: float = COL_SLACK,
                     view: ObservationView | None = None) -> np.ndarray:
    """Bool ``(H, W)``: the cells of the objects that do not look sorted in ``obs`` but whose blob centroid lies
    within their class's region widened as the module docstring says. ``view``: ``obs`` already read
    (`ObservationView.from_observation` with ``margin_cells=0``), so that a caller who holds it does not read it
    twice."""
    obs = np.asarray(obs)
    if obs.ndim != 3 or obs.shape[0] != 4:
        raise ValueError(f"borderline_cells reads one (4, H, W) observation, got shape {obs.shape}")
    rows, cols = obs.shape[1:]
    width = int(round(params.REGION_WIDTH / (params.CABINET_WIDTH / cols)))
    view = ObservationView.from_observation(obs, margin_cells=0) if view is None else view
    out = np.zeros((rows, cols), bool)
    for b in range(int(view.blob.max()) + 1):
        cells = view.blob == b
        rect = view.regions[int(view.object_class[cells][0])]
        if rect is None or view.sorted_cells[cells].any():
            continue
        rr, cc = np.nonzero(cells)
        r, c = rr.mean(), cc.mean()
        lo, hi = min(rect[2], rect[3] - width + 1), max(rect[3], rect[2] + width - 1)
        if rect[0] - row_slack <= r <= rect[1] + row_slack and lo - col_slack <= c <= hi + col_slack:
            out |= cells
    return out


class EdgeGuard(PickMask):
    """Wrap ``policy`` (SB3's ``predict`` with ``action_masks``): the borderline objects' pick cells are masked
    while an allowed pick on another object is left (module docstring)."""

    STATS = ("deferred", "released")

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True, action_masks: np.ndarray | None = None) -> tuple[np.ndarray, Any]:
        obs, allowed = self.observation(observation), self.allowed(action_masks)
        edge = borderline_cells(obs)
        picks = allowed.reshape(self.n_maps, self.rows, self.cols)[self.pick]
        if not (picks & ~edge).any():  # only borderline objects (or none) left to pick: their turn
            self.stats["released"] += int((picks & edge).any())
            return self.policy.predict(obs, state=state, deterministic=deterministic, action_masks=allowed)
        return self.choose(obs, allowed, edge, state, deterministic)


def _wrap(agent: Any, env: gym.Env, base: str) -> EdgeGuard:
    unwrapped: Any = env.unwrapped
    return EdgeGuard(agent, tuple(unwrapped.map_names), unwrapped.rows, unwrapped.cols)


register_wrapper(EDGE_GUARD, _wrap)


def greedy_stats(folder: pathlib.Path, max_shards: str) -> dict[str, int]:
    """Counts over the shards ``max_shards`` selects (`select_shards`' spec): the driver's greedy picks on an object
    by outcome (``sorted``: the sorted count rose and the scene stayed valid; ``same``: valid, unchanged;
    ``unsorted``: valid, fell; ``invalid``), each also counted where the object is borderline."""
    from research.fall_risk import teacher_split
    from shelf_env.privileged import dataset

    counts: dict[str, int] = {}
    shards = dataset.select_shards(dataset.load_dataset(folder), max_shards)
    picks = teacher_split(shards, np.arange(sum(s.num_states for s in shards)), source="greedy")
    assert picks.sorted_change is not None  # a teacher dataset's split has it
    cols = picks.obs.shape[-1]
    for state, cell, invalid, d in zip(picks.state.numpy(), picks.cell.numpy(), picks.label.numpy(),
                                       picks.sorted_change):
        obs = picks.obs[int(state)].numpy()
        r, c = divmod(int(cell), cols)
        view = ObservationView.from_observation(obs, margin_cells=0)
        if view.blob[r, c] < 0:
            continue
        kind = "invalid" if invalid else "sorted" if d > 0 else "same" if d == 0 else "unsorted"
        counts[kind] = counts.get(kind, 0) + 1
        if borderline_cells(obs, view=view)[r, c]:
            counts[kind + "_borderline"] = counts.get(kind + "_borderline", 0) + 1
    return counts


def stats_table(folder: pathlib.Path, max_shards: str) -> str:
    """`greedy_stats` as a markdown table."""
    c = greedy_stats(folder, max_shards)
    total = sum(c.get(k, 0) for k in ("sorted", "same", "unsorted", "invalid"))
    if total == 0:
        raise ValueError(f"{folder} --max-shards {max_shards}: no greedy pick on an object")
    lines = [f"Greedy picks on an object in `{folder}` (`--max-shards {max_shards}`): {total}", "",
             "| outcome | picks | share | borderline | share of the outcome borderline |", "|---|---|---|---|---|"]
    for kind in ("sorted", "same", "unsorted", "invalid"):
        n, b = c.get(kind, 0), c.get(kind + "_borderline", 0)
        lines.append(f"| {kind} | {n} | {100 * n / total:.1f} % | {b} | {100 * b / max(n, 1):.1f} % |")
    return "\n".join(lines) + "\n"


def live_counts(policy: str, n: int, runs: int, first_seed: int, object_set: str) -> dict[str, int]:
    """``policy`` played greedily on ``runs`` scenes (seeds ``first_seed``...) of ``n`` objects: its picks by what
    the env's rule says of the object it moved most (sorted before -> after; ``invalid``: the step was not valid) and
    by how the observation read that object (``looked_sorted``, ``borderline``, else ``clear``)."""
    import shelf_env  # noqa: F401  (registers ShelfSort-v0)
    from shelf_env.policies import make_policy
    from shelf_env.world.task import judge

    env = gym.make("ShelfSort-v0", num_objects=n, object_set=object_set, pixel_size=0.01)
    u: Any = env.unwrapped
    agent = make_policy(policy, env)
    counts: dict[str, int] = {}
    try:
        for run in range(runs):
            obs, _ = env.reset(seed=first_seed + run)
            start, done = True, False
            while not done:
                action, _ = agent.predict(obs, deterministic=True, episode_start=[start],
                                          action_masks=u.action_masks())
                start = False
                primitive, r, c = u.codec.decode(int(np.asarray(action).reshape(-1)[0]))
                before, was = u.world.positions().copy(), judge(u.world)
                view = ObservationView.from_observation(obs, margin_cells=0)
                reading = ("looked_sorted" if view.sorted_cells[r, c]
                           else "borderline" if borderline_cells(obs, view=view)[r, c] else "clear")
                obs, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
                if primitive != "pick":
                    continue
                after, now = u.world.positions(), judge(u.world)
                if after.shape != before.shape or not now.valid:
                    kind = "invalid"
                else:
                    moved = int(np.argmax(np.linalg.norm(after[:, :2] - before[:, :2], axis=1)))
                    own_before, own_after = (was.region == was.classes)[moved], (now.region == now.classes)[moved]
                    kind = f"{'sorted' if own_before else 'unsorted'}->{'sorted' if own_after else 'unsorted'}"
                key = f"{kind}|{reading}"
                counts[key] = counts.get(key, 0) + 1
    finally:
        env.close()
    return counts


def live_table(policy: str, n: int, runs: int, first_seed: int, object_set: str) -> str:
    """`live_counts` as a markdown table."""
    c = live_counts(policy, n, runs, first_seed, object_set)
    total = sum(c.values())
    readings = ("clear", "borderline", "looked_sorted")
    lines = [f"`{policy}`, {runs} scenes of {n} {object_set} objects (seeds {first_seed}..{first_seed + runs - 1}): "
             f"{total} picks", "", "| the object moved (env's rule) | " + " | ".join(readings) + " | all |",
             "|---|" + "---|" * (len(readings) + 1)]
    for kind in ("unsorted->sorted", "sorted->sorted", "unsorted->unsorted", "sorted->unsorted", "invalid"):
        row = [c.get(f"{kind}|{r}", 0) for r in readings]
        share = 100 * sum(row) / max(total, 1)
        lines.append(f"| {kind} | " + " | ".join(str(v) for v in row) + f" | {sum(row)} ({share:.1f} %) |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m research.edge_guard", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    s = sub.add_parser("stats", help="a series' greedy picks by outcome and by the borderline reading")
    s.add_argument("data", type=pathlib.Path)
    s.add_argument("--max-shards", required=True, help="the shards read (select_shards' spec, e.g. s05:200)")
    s.add_argument("--out", type=pathlib.Path, default=None, help="write the table here (else print it)")
    v = sub.add_parser("live", help="a policy's picks on training-seed scenes, judged by the env's rule")
    v.add_argument("--policy", default="examples/pretrained/p_s.zip+geometry-filter+pick-guard+loop-breaker")
    v.add_argument("--n", type=int, default=8)
    v.add_argument("--runs", type=int, default=20)
    v.add_argument("--first-seed", type=int, default=7000)
    v.add_argument("--object-set", default="ycb")
    v.add_argument("--out", type=pathlib.Path, default=None, help="write the table here (else print it)")
    args = parser.parse_args(argv)
    if args.command == "stats":
        return table_command(lambda: stats_table(args.data, args.max_shards), args.out)
    if args.runs < 1 or not 1 <= args.n <= params.MAX_OBJECTS:
        print(f"research.edge_guard live: need --runs >= 1 and 1 <= --n <= {params.MAX_OBJECTS}", file=sys.stderr)
        return 2
    return table_command(lambda: live_table(args.policy, args.n, args.runs, args.first_seed, args.object_set), args.out)


if __name__ == "__main__":
    sys.exit(main())
