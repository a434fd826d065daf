"""Why evaluation episodes failed, from replayed traces: which motion made an object leave the cabinet.

    python -m shelf_env.evaluation.traces results/models --policies examples/pretrained/p_s.zip h-d --ns 8 14

Evaluation episodes are history-free (`shelf_env.env`): episode ``run`` of a cell starts from
`evaluation.scene_seed` and a greedy policy acts deterministically, so any episode of a
``shelf-evaluate`` folder can be replayed exactly. This module replays the folder's failed episodes
(those whose cell records ``failure == "fell"`` by default) and watches the world between the
phases of each action, which the evaluation's records do not:

- ``pick``: descend, grip, lift and carry the held object out of the opening;
- ``place``: carry it back in, lower, release and retreat;
- ``push``: the whole straight push and retreat;
- ``settle``: the world settling after the arm has gone.

For every object that left the cabinet it reports the phase after which it was first outside and
whether it was the object in the cup (a neighbour dragged out by the pick's carry is the case of
§V-d and of issue 13's closed loop). Within a pick it also names the motion (``motion``):
``approach`` (in and down to the object), ``lift``, ``retreat`` (the carry out of the opening) or,
with the closed loop (`shelf_env.conditions.closed_loop.DragWatch`), ``put down`` (its reaction: the object carried
back and put down). It writes ``<folder>/traces.jsonl`` (one line per replayed episode) and
``<folder>/falls.md`` (counts per policy and N, by phase and by pick motion), and says when a
replay does not reproduce its record (it would mean the episode was not history-free).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
from collections import Counter
from typing import Any

import gymnasium as gym

from shelf_env.evaluation import protocol as ev
from shelf_env.files import write_atomically

#: The phases a fall is attributed to, in the order they happen within an action.
PHASES = ("pick", "place", "push", "settle")
#: The motions of a pick a fall is attributed to (``motion``), in the order they happen.
PICK_MOTIONS = ("approach", "lift", "detour", "retreat", "put down")


def _outside(world: Any) -> set[int]:
    """Uids of the objects that are not in the cabinet's interior box now."""
    if not world.objects:
        return set()
    inside = world.inside(world.positions())
    return {o.uid for o, ok in zip(world.objects, inside) if not ok}


class PhaseWatch:
    """Wraps an env's primitives to note, after each phase, which objects are outside the cabinet.

    The held object is outside by design at the end of the pick (the carry ends in front of the
    opening), so it is only counted as fallen if it is still outside after ``place``. Attach it
    after ``reset`` / ``set_scene``: they rebuild the world and the primitives."""

    def __init__(self, env: gym.Env):
        base: Any = env.unwrapped  # a ShelfSortEnv
        self.world = base.world
        self.runner = base.primitive_runner
        self.first_out: dict[int, str] = {}
        self.first_motion: dict[int, str] = {}
        self.held: int | None = None
        pick, place, push = self.runner.pick, self.runner.place, self.runner.push
        # the carried moves (every pick's; a closed loop watches them) and a closed loop's put-down
        carry_move, put_down = self.runner._carry_move, getattr(self.runner, "_put_down_here", None)
        moving = [""]

        def watched(start: Any, end: Any, speed: float, phase: str) -> Any:
            self._note_motion("approach" if phase == "lift" else "lift")  # what happened before this move
            moving[0] = phase
            caught = carry_move(start, end, speed, phase)
            self._note_motion(phase)
            return caught

        def watched_put_down(*args: Any, **kwargs: Any) -> Any:
            self._note_motion(moving[0])  # out before the catch: the move that was caught
            assert put_down is not None
            result = put_down(*args, **kwargs)
            self._note_motion("put down")
            return result

        self.runner._carry_move = watched
        if put_down is not None:
            self.runner._put_down_here = watched_put_down

        def watched_pick(*args: Any, **kwargs: Any) -> Any:
            grasp = pick(*args, **kwargs)
            self.held = None if grasp is None else grasp.uid
            self._note("pick", exclude=self.held)
            return grasp

        def watched_place(*args: Any, **kwargs: Any) -> Any:
            result = place(*args, **kwargs)
            self._note("place")
            return result

        def watched_push(*args: Any, **kwargs: Any) -> Any:
            result = push(*args, **kwargs)
            self._note("push")
            return result

        self.runner.pick, self.runner.place, self.runner.push = watched_pick, watched_place, watched_push

    def _note(self, phase: str, exclude: int | None = None) -> None:
        for uid in _outside(self.world) - {exclude}:
            self.first_out.setdefault(uid, phase)

    def _note_motion(self, motion: str) -> None:
        held = self.runner.robot.held[0] if self.runner.robot.held else None
        for uid in _outside(self.world) - {held}:
            self.first_motion.setdefault(uid, motion)

    def begin_action(self) -> None:
        self.first_out, self.first_motion, self.held = {}, {}, None

    def end_action(self, uids_before: set[int]) -> list[dict[str, Any]]:
        """The objects that left the cabinet during the action just taken (the env removes them
        when it judges the step, so they are those of ``uids_before`` no longer in the world)."""
        gone = uids_before - {o.uid for o in self.world.objects}
        fell: list[dict[str, Any]] = []
        for uid in sorted(gone):
            phase = self.first_out.get(uid, "settle")
            fell.append({"uid": uid, "phase": phase, "held": uid == self.held})
            if phase == "pick":  # not seen after any watched move: a pick that found nothing to grip
                fell[-1]["motion"] = self.first_motion.get(uid, "approach")
        return fell


class FallTrace(gym.Wrapper):
    """An env that records, per action, its primitive and the objects that left the cabinet
    (`PhaseWatch.end_action`) in ``steps``; each ``reset`` starts a new trace on the new world."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.steps: list[dict[str, Any]] = []
        self.watch: PhaseWatch | None = None

    def reset(self, **kwargs: Any) -> Any:
        result = self.env.reset(**kwargs)
        self.watch, self.steps = PhaseWatch(self.env), []  # after reset: it rebuilt the world
        return result

    def step(self, action: Any) -> Any:
        if self.watch is None:
            raise RuntimeError("call reset() before step()")
        before = {o.uid for o in self.watch.world.objects}
        self.watch.begin_action()
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps.append({"primitive": info["primitive"], "fell": self.watch.end_action(before)})
        return obs, reward, terminated, truncated, info


def replay(policy: str, num_objects: int, seed: int, run: int, object_set: str = "ycb",
           conditions: dict[str, Any] | None = None) -> dict[str, Any]:
    """Replay one evaluation episode (the env, scene, greedy policy and rollout of
    `evaluation.evaluate_cell`, under the evaluation's ``conditions``) and return its record's
    outcome with its trace: per action the primitive, and the objects that left the cabinet with
    the phase and whether it was held."""
    env = FallTrace(ev.make_env(policy, num_objects, object_set, conditions=conditions))
    try:
        agent = ev.make_policy(policy, env, seed=ev.scene_seed(seed, num_objects, 10**6))
        outcome = ev.run_episode(env, agent, ev.scene_seed(seed, num_objects, run))
        return {"policy": ev.policy_label(policy), "object_set": object_set, "num_objects": num_objects,
                "seed": seed, "run": run, "success": outcome["success"], "fell": outcome["fell"],
                "actions": outcome["actions"], "steps": env.steps}
    finally:
        env.close()


def fall_counts(traces: list[dict[str, Any]]) -> Counter:
    """``{(policy, N, cause): objects}`` with cause ``"<phase>, held"`` or ``"<phase>, neighbour"``."""
    counts: Counter = Counter()
    for t in traces:
        for step in t["steps"]:
            for f in step["fell"]:
                cause = f"{f['phase']}, {'held' if f['held'] else 'neighbour'}"
                counts[(t["policy"], t["num_objects"], cause)] += 1
    return counts


def falls_table(traces: list[dict[str, Any]]) -> str:
    """Markdown: objects that left the cabinet per (policy, N), by phase and held/neighbour."""
    counts = fall_counts(traces)
    causes = sorted({c for _, _, c in counts}, key=lambda c: (PHASES.index(c.split(",")[0]), c))
    episodes = Counter((t["policy"], t["num_objects"]) for t in traces)
    lines = ["| policy | N | episodes replayed | " + " | ".join(causes) + " |",
             "|---|---|---|" + "---|" * len(causes)]
    for policy, n in sorted(episodes):
        lines.append(f"| {policy} | {n} | {episodes[(policy, n)]} | "
                     + " | ".join(str(counts.get((policy, n, c), 0)) for c in causes) + " |")
    return "\n".join(lines) + "\n"


def motions_table(traces: list[dict[str, Any]]) -> str:
    """Markdown: objects that left the cabinet during a pick, per (policy, N), by the pick's motion
    (`PICK_MOTIONS`); traces written before the field existed count as ``unrecorded``."""
    counts: Counter = Counter()
    for t in traces:
        for step in t["steps"]:
            for f in step["fell"]:
                if f["phase"] == "pick":
                    counts[(t["policy"], t["num_objects"], f.get("motion", "unrecorded"))] += 1
    motions = [m for m in (*PICK_MOTIONS, "unrecorded") if any(k[2] == m for k in counts)]
    keys = sorted({(p, n) for p, n, _ in counts})
    lines = ["| policy | N | " + " | ".join(motions) + " |", "|---|---|" + "---|" * len(motions)]
    lines += [f"| {p} | {n} | " + " | ".join(str(counts.get((p, n, m), 0)) for m in motions) + " |" for p, n in keys]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m shelf_env.evaluation.traces", description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=pathlib.Path, help="a shelf-evaluate --out folder (its cells are replayed)")
    parser.add_argument("--policies", nargs="+", required=True, help="as given to shelf-evaluate (names or zips)")
    parser.add_argument("--ns", nargs="+", type=int, required=True, help="numbers of objects to replay")
    parser.add_argument("--failure", default="fell", choices=ev.FAILURES, help="which failed episodes to replay")
    parser.add_argument("--limit", type=int, default=0, help="at most this many episodes per (policy, N); 0: all")
    args = parser.parse_args(argv)
    try:
        for policy in args.policies:
            ev.check_policy(policy)
        ev.check_ns(args.ns)
        ev.check_cell_owner(args.folder, args.policies)
        conditions = ev.folder_conditions(args.folder)  # replayed under the conditions they ran in
        evaluated = ev.load_cells(args.folder)
    except ValueError as err:
        print(f"traces: error: {err}", file=sys.stderr)
        return 2
    by_label = {ev.policy_label(p): p for p in args.policies}
    chosen: dict[tuple[str, int], list[ev.EpisodeRecord]] = {}
    for r in evaluated:
        if r.policy in by_label and r.num_objects in args.ns and r.failure == args.failure:
            chosen.setdefault((r.policy, r.num_objects), []).append(r)
    traces, mismatches = [], 0
    for (label, n), records in sorted(chosen.items()):
        for r in records[: args.limit or None]:
            trace = replay(by_label[label], n, r.seed, r.run, r.object_set, conditions)
            if (trace["fell"], trace["actions"], trace["success"]) != (r.fell, r.actions, r.success):
                mismatches += 1
                trace["mismatch"] = {"recorded": {"fell": r.fell, "actions": r.actions, "success": r.success}}
            traces.append(trace)
            print(f"{label} N={n} seed {r.seed} run {r.run}: "
                  + "; ".join(f"{f['phase']} ({'held' if f['held'] else 'neighbour'})"
                              for s in trace["steps"] for f in s["fell"]), flush=True)
    write_atomically(args.folder / "traces.jsonl",
                     lambda tmp: tmp.write_text("".join(json.dumps(t) + "\n" for t in traces)))
    command = " ".join(["python -m shelf_env.evaluation.traces", *(sys.argv[1:] if argv is None else argv)])
    table = falls_table(traces)
    motions = motions_table(traces)
    write_atomically(args.folder / "falls.md",
                     lambda tmp: tmp.write_text(f"Objects that left the cabinet, by phase (`{command}`):\n\n{table}"
                                                f"\nThose that left during a pick, by its motion:\n\n{motions}"))
    print(table, end="")
    print(motions, end="")
    if mismatches:
        print(f"warning: {mismatches} replays did not reproduce their records", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
