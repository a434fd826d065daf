"""Fall traces (shelf_env.evaluation.traces): the phase and the object a fall comes from, on a crafted drag and
on a replayed evaluation episode that must reproduce its record."""

from __future__ import annotations

import json

import gymnasium as gym
import pybullet as pb
import pytest

from shelf_env.evaluation import protocol as ev
from shelf_env.evaluation import traces
from tests.conftest import REGIONS
from tests.test_closed_loop import CLEAN_SCENE, DRAG_SCENE

# An evaluation episode where H-d's first action drops an object out of the cabinet (found in
# scripts/evaluate_models.sh's cells: h-d, YCB, N = 3, seed 2, run 16: 1 action, fell).
FELL = ev.EpisodeRecord("h-d", "ycb", 3, 2, 16, success=False, actions=1, num_unsorted_initial=1, fell=True,
                        noops=0, failure="fell", max_repeat=1)


def watched_pick(scene, closed_loop=False, knock=None):
    """Pick the back box of ``scene`` with a `PhaseWatch`; ``knock(runner, knock_out)`` may first wrap
    one of the runner's motions so that it ends with ``knock_out()``: the object nearest the opening
    moved out of the cabinet by hand, as a fall during that motion would."""
    env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=closed_loop)
    try:
        env.reset(seed=0)
        env.unwrapped.set_scene(scene, REGIONS)
        world = env.unwrapped.world
        front = world.objects[int(world.positions()[:, 0].argmin())].uid  # nearest the opening
        if knock is not None:
            knock(env.unwrapped.primitive_runner, lambda: pb.resetBasePositionAndOrientation(
                front, (-0.15, 0.0, 0.05), (0, 0, 0, 1), physicsClientId=env.unwrapped.client))
        watch = traces.PhaseWatch(env)
        before = {o.uid for o in world.objects}
        watch.begin_action()
        _, _, _, _, info = env.step(env.unwrapped.codec.action_at("pick", 0.30, 0.0))
        return info, watch.end_action(before), front
    finally:
        env.close()


def test_a_neighbour_dragged_out_by_the_pick_is_traced_to_the_pick():
    info, fell, front = watched_pick(DRAG_SCENE)
    assert info["fell"] and fell == [{"uid": front, "phase": "pick", "held": False, "motion": "retreat"}]
    info, fell, _ = watched_pick(CLEAN_SCENE)
    assert not info["fell"] and fell == []


def test_a_fall_during_the_closed_loops_put_down_is_traced_to_it():
    # the closed loop catches the crafted drag and carries the box back; a put-down that then
    # knocks the neighbour out (here: moved out by hand, as a fall in that motion would) is named
    def knock_after_put_down(runner, knock_out):
        put_down = runner._put_down_here

        def knocking_put_down(*args, **kwargs):
            carried = put_down(*args, **kwargs)
            knock_out()
            return carried

        runner._put_down_here = knocking_put_down

    info, fell, front = watched_pick(DRAG_SCENE, {"lane": False}, knock_after_put_down)
    assert info["interventions"] and info["fell"]
    assert fell == [{"uid": front, "phase": "pick", "held": False, "motion": "put down"}]
    table = traces.motions_table([{"policy": "h-d", "num_objects": 2, "steps": [{"fell": fell}]},
                                  {"policy": "h-d", "num_objects": 2, "steps": [{"fell": [{"phase": "pick"}]}]}])
    assert table == "| policy | N | put down | unrecorded |\n|---|---|---|---|\n| h-d | 2 | 1 | 1 |\n"


def test_replayed_fall_reproduces_its_record_and_is_tabled(tmp_path, capsys):
    ev.save_cell(ev.cell_path(tmp_path, "h-d", "ycb", 3, 2, 1), [FELL])
    assert traces.main([str(tmp_path), "--policies", "h-d", "--ns", "3"]) == 0
    out = capsys.readouterr()
    assert "did not reproduce" not in out.err
    (trace,) = [json.loads(line) for line in (tmp_path / "traces.jsonl").read_text().splitlines()]
    assert (trace["fell"], trace["actions"], trace["success"]) == (True, 1, False) and "mismatch" not in trace
    (step,) = trace["steps"]
    assert step["primitive"] == "pick" and len(step["fell"]) >= 1
    assert all(f["phase"] in traces.PHASES for f in step["fell"])
    table = (tmp_path / "falls.md").read_text()
    assert table.startswith("Objects that left the cabinet, by phase (`python -m shelf_env.evaluation.traces "
                            f"{tmp_path} --policies h-d --ns 3`):")
    assert "| policy | N | episodes replayed |" in table and "| h-d | 3 | 1 |" in table
    assert sum(traces.fall_counts([trace]).values()) == len(step["fell"])


def test_bad_input_is_one_line(tmp_path, capsys):
    assert traces.main([str(tmp_path), "--policies", "h-d", "--ns", "3"]) == 2
    assert "has no evaluation cells" in capsys.readouterr().err
    assert traces.main([str(tmp_path), "--policies", "nope.zip", "--ns", "3"]) == 2
    assert "nope.zip" in capsys.readouterr().err


def test_episodes_are_replayed_under_the_folders_conditions(tmp_path, monkeypatch):
    ev.save_cell(ev.cell_path(tmp_path, "h-d", "ycb", 3, 2, 1), [FELL])
    (tmp_path / "conditions.json").write_text(json.dumps({"safe_picks": True}))
    seen = []

    def make_env(policy, num_objects, object_set="ycb", primitives=None, conditions=None):
        seen.append(conditions)
        raise RuntimeError("stop here")

    monkeypatch.setattr(ev, "make_env", make_env)
    with pytest.raises(RuntimeError, match="stop here"):
        traces.main([str(tmp_path), "--policies", "h-d", "--ns", "3"])
    assert seen == [{"safe_picks": True}]
    (tmp_path / "conditions.json").write_text(json.dumps({"closed_loop": "yes"}))
    assert traces.main([str(tmp_path), "--policies", "h-d", "--ns", "3"]) == 2  # bad conditions: one line


def test_a_fall_during_the_lane_checks_sideways_carry_is_traced_to_the_detour():
    # the lane check carries the box sideways past the front one; a detour that knocked the front
    # one out (moved out by hand, as in the test above) is named
    def knock_after_detour(runner, knock_out):
        watched_move = runner._carry_move

        def knocking_detour(start, end, speed, phase):
            caught = watched_move(start, end, speed, phase)
            if phase == "detour":
                knock_out()
            return caught

        runner._carry_move = knocking_detour

    info, fell, front = watched_pick(DRAG_SCENE, True, knock_after_detour)
    assert [e["phase"] for e in info["interventions"]] == ["lane"] and info["fell"]
    assert fell == [{"uid": front, "phase": "pick", "held": False, "motion": "detour"}]
