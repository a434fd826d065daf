"""Closed-loop primitives (`ShelfSortEnv(closed_loop=True)`, `shelf_env.conditions.closed_loop.DragWatch`): the retract
after a pick that drags a neighbour out of the cabinet open loop is caught by the cup's force
sensor and the object is put down; a clean pick is left alone."""

from __future__ import annotations

import gymnasium as gym
import pytest

from shelf_env.conditions.closed_loop import DragWatch
from shelf_env.world.objects import ObjectSpec
from tests.conftest import REGIONS


def tall(h: float, mass: float) -> ObjectSpec:
    return ObjectSpec("cuboid", "box", (0.05, 0.05, h), mass)


# a 14 cm box at the back, a light 10 cm box in front of it near the opening: the picked box hangs
# low enough under the cup to drag the front one out as it is carried out
DRAG_SCENE = [(tall(0.14, 0.3), 1, 0.30, 0.0, 0.0), (tall(0.10, 0.15), 2, 0.06, 0.0, 0.0)]
CLEAN_SCENE = [(tall(0.14, 0.3), 1, 0.30, 0.0, 0.0), (tall(0.10, 0.15), 2, 0.06, 0.20, 0.0)]


def pick_back_box(scene, closed_loop: bool, physics: str = "fast"):
    env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=closed_loop, physics=physics).unwrapped
    try:
        env.reset(seed=0)
        env.set_scene(scene, REGIONS)
        _, reward, terminated, _, info = env.step(env.codec.action_at("pick", 0.30, 0.0))
        return reward, terminated, info, env.world.positions()
    finally:
        env.close()


def test_open_loop_retract_drags_the_neighbour_out():
    reward, terminated, info, _ = pick_back_box(DRAG_SCENE, closed_loop=False)
    assert info["fell"] and reward == -10 and terminated
    assert "interventions" not in info  # open loop reports nothing


def test_closed_loop_catches_the_drag_and_puts_the_object_down():
    # the watches alone (no lane check, which would not let the drag start)
    reward, terminated, info, positions = pick_back_box(DRAG_SCENE, closed_loop={"lane": False})
    assert not info["fell"] and reward == -1 and not terminated
    (event,) = info["interventions"]
    assert event["primitive"] == "pick" and event["phase"] == "retreat" and event["signal"] == "force"
    assert event["force_n"] > 0.25
    # the default reaction carries the box back the whole way it came and puts it down where it was picked
    carried = float(event["reaction"].removeprefix("carried back ").removesuffix(" m, put down"))
    assert carried == pytest.approx(0.30 - event["tcp"][0], abs=0.01)
    assert len(positions) == 2 and (positions[:, 0] > 0).all()  # both objects still inside
    assert positions[0] == pytest.approx([0.30, 0.0, 0.07], abs=0.005)


def test_a_short_back_off_puts_the_object_down_where_it_was_caught():
    reward, terminated, info, positions = pick_back_box(DRAG_SCENE, closed_loop=DragWatch(back_off=0.02, lane=False))
    assert not info["fell"] and not terminated
    (event,) = info["interventions"]
    assert event["reaction"] == "carried back 0.020 m, put down"
    caught_x = event["tcp"][0]
    assert positions[0, 0] == pytest.approx(caught_x + 0.02 + 0.0025, abs=0.01)  # the box hangs 2.5 mm behind the TCP
    assert (positions[:, 0] > 0).all()


def test_the_camera_check_sees_the_dragged_neighbour_come_towards_the_opening():
    # force sensor off: only the camera watches; the neighbour is hidden under the carried box for
    # most of the drag, so the camera sees it late (and it still falls), but it names the right object
    env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=DragWatch(force=False, lane=False)).unwrapped
    try:
        env.reset(seed=0)
        env.set_scene(DRAG_SCENE, REGIONS)
        back, front = (o.uid for o in env.world.objects)
        edges = env.watch_camera.front_edges([back, front])
        # each box's front face (5 cm deep boxes at x = 0.30 and 0.06)
        assert edges == {back: pytest.approx(0.275, abs=0.005), front: pytest.approx(0.035, abs=0.005)}
        _, _, _, _, info = env.step(env.codec.action_at("pick", 0.30, 0.0))
    finally:
        env.close()
    (event,) = info["interventions"]
    assert event["signal"] == "camera" and event["object"] == front and event["shift_m"] > DragWatch().camera_shift


def test_closed_loop_takes_a_drag_watch_and_refuses_anything_else():
    env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=DragWatch(threshold=0.5)).unwrapped
    try:
        assert env.drag_watch == DragWatch(threshold=0.5) and env.watch_camera is not None
    finally:
        env.close()
    open_env = gym.make("ShelfSort-v0", num_objects=2).unwrapped
    try:
        assert open_env.drag_watch is None and open_env.watch_camera is None
    finally:
        open_env.close()
    with pytest.raises(ValueError, match="closed_loop must be True, False, a dict of DragWatch fields or a DragWatch"):
        gym.make("ShelfSort-v0", num_objects=2, closed_loop="yes")


def test_closed_loop_leaves_a_clean_pick_alone():
    # every motion simulated, so that the watched moves (always simulated) compare step for step
    open_loop = pick_back_box(CLEAN_SCENE, closed_loop=False, physics="reference")
    closed = pick_back_box(CLEAN_SCENE, closed_loop=True, physics="reference")
    assert closed[2]["interventions"] == []
    assert closed[0] == open_loop[0] and not closed[2]["fell"]
    assert closed[3] == pytest.approx(open_loop[3], abs=1e-6)  # the same motion, bit for bit up to float noise


@pytest.mark.parametrize("fields, message", [
    ({"sustian": 2}, r"unknown closed_loop keys \['sustian'\]"),
    ({"threshold": -0.1}, "DragWatch.threshold must be a finite number >= 0"),
    ({"camera_shift": float("nan")}, "DragWatch.camera_shift must be a finite number >= 0"),
    ({"sustain": 0}, "DragWatch.sustain must be >= 1"),
    ({"camera_every": 1.5}, "DragWatch.camera_every must be an integer >= 0"),
    ({"speed_scale": 0}, r"DragWatch.speed_scale must be in \(0, 1\]"),
    ({"force": 1}, "DragWatch.force must be True or False"),
    ({"lane": "yes"}, "DragWatch.lane must be True or False"),
    ({"detour_max": -0.1}, "DragWatch.detour_max must be a finite number >= 0"),
    ({"blocked": "drop"}, r"DragWatch.blocked must be one of \('carry', 'put back'\), got 'drop'"),
    ({"place_check": 1}, "DragWatch.place_check must be True or False"),
    ({"stack_height": -0.01}, "DragWatch.stack_height must be a finite number >= 0"),
    ({"stack_front": float("inf")}, "DragWatch.stack_front must be a finite number >= 0"),
    ({"stacked": "drop"}, r"DragWatch.stacked must be one of \('deeper', 'put back'\), got 'drop'"),
])
def test_bad_watch_fields_are_named(fields, message):
    with pytest.raises(ValueError, match=message):
        DragWatch.from_any(fields)


def test_from_any_reads_the_env_argument():
    assert DragWatch.from_any(False) is None and DragWatch.from_any(True) == DragWatch()
    assert DragWatch.from_any({"sustain": 2}) == DragWatch(sustain=2)
    watch = DragWatch(force=False)
    assert DragWatch.from_any(watch) is watch


def test_speed_scale_slows_the_watched_retreat():
    # the retreat of the clean pick (0.30 -> out of the opening, ~0.4 m at 0.25 m/s) is always simulated
    # (a watched move); at half speed it takes ~twice the physics steps, and nothing is caught
    steps = {}
    for scale in (1.0, 0.5):
        env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=DragWatch(speed_scale=scale)).unwrapped
        try:
            env.reset(seed=0)
            env.set_scene(CLEAN_SCENE, REGIONS)
            before = env.robot.physics_steps
            _, _, _, _, info = env.step(env.codec.action_at("pick", 0.30, 0.0))
            steps[scale] = env.robot.physics_steps - before
            assert info["interventions"] == [] and not info["fell"]
        finally:
            env.close()
    retreat = 0.40 / (0.25 * 1 / 240)  # physics steps of the retreat at full speed (TIME_STEP 1/240 s)
    assert steps[0.5] - steps[1.0] == pytest.approx(retreat, rel=0.25)


def test_the_lane_check_carries_the_object_out_beside_the_neighbour_it_would_drag():
    # DRAG_SCENE: the 14 cm box hangs 4.5 cm above the floor under the cup, the 10 cm box in front
    # is in its way (open loop it is dragged out); the lane check shifts the carry sideways first
    reward, terminated, info, positions = pick_back_box(DRAG_SCENE, closed_loop=True)  # the defaults
    assert not info["fell"] and not terminated
    (event,) = info["interventions"]
    assert event["phase"] == "lane" and event["signal"] == "lane"
    shift = float(event["reaction"].removeprefix("carried ").removesuffix(" m sideways, then out"))
    assert 0.05 < abs(shift) < 0.08  # half the two 5 cm widths, their margins and the cell grid
    assert positions[1] == pytest.approx([0.06, 0.0, 0.05], abs=0.003)  # the front box untouched
    assert positions[0, 0] != pytest.approx(0.30, abs=0.01)  # the back box was carried out and placed


def test_the_lane_check_puts_the_object_back_when_no_way_out_is_clear():
    watch = {"detour_max": 0.0}  # blocked="put back" is the default
    reward, terminated, info, positions = pick_back_box(DRAG_SCENE, closed_loop=watch)
    assert not info["fell"] and not terminated
    (event,) = info["interventions"]
    assert event["phase"] == "lane" and event["reaction"] == "no clear way out: put back where picked"
    assert positions[0] == pytest.approx([0.30, 0.0, 0.07], abs=0.005)  # back where it was picked
    assert positions[1] == pytest.approx([0.06, 0.0, 0.05], abs=0.003)
    # blocked="carry" carries it straight out, and the force watch catches the drag
    _, _, info, _ = pick_back_box(DRAG_SCENE, closed_loop={"blocked": "carry", "detour_max": 0.0})
    assert [e["signal"] for e in info["interventions"]] == ["force"]


def test_the_watches_without_the_lane_check_leave_a_clean_pick_alone_too():
    open_loop = pick_back_box(CLEAN_SCENE, closed_loop=False, physics="reference")
    closed = pick_back_box(CLEAN_SCENE, closed_loop={"lane": False}, physics="reference")
    assert closed[2]["interventions"] == [] and closed[0] == open_loop[0]
    assert closed[3] == pytest.approx(open_loop[3], abs=1e-6)


# a 10 cm box picked at the back, and a low wide 6 cm box near the opening: placed with its centre
# 5 cm behind the opening, the picked box lands with its back on the low one, tips forward and
# falls out open loop
STACK_SCENE = [(tall(0.10, 0.3), 1, 0.30, 0.20, 0.0),
               (ObjectSpec("cuboid", "box", (0.10, 0.12, 0.06), 0.3), 2, 0.10, 0.0, 0.0)]


def pick_and_place(closed_loop, place_x: float):
    """Pick STACK_SCENE's back box and place it at (place_x, 0): the primitives themselves, so that
    the place pose is the test's and not the place heuristic's."""
    env = gym.make("ShelfSort-v0", num_objects=2, closed_loop=closed_loop).unwrapped
    try:
        env.reset(seed=0)
        env.set_scene(STACK_SCENE, REGIONS)
        runner = env.primitive_runner
        grasp = runner.pick(0.30, 0.20, 0.10, {o.uid for o in env.world.objects})
        assert grasp is not None and (grasp.x, grasp.y, grasp.lane_y) == (0.30, 0.20, 0.20)
        runner.place(grasp, place_x, 0.0)
        env.robot.hold_still(240)
        return env.world.positions(), runner.interventions
    finally:
        env.close()


def test_open_loop_place_on_an_object_at_the_opening_drops_the_held_one_out():
    positions, interventions = pick_and_place({"place_check": False}, 0.05)
    assert positions[0, 0] < 0 and interventions == []  # out of the cabinet
    positions, _ = pick_and_place(False, 0.05)
    assert positions[0, 0] < 0


def test_the_place_check_puts_the_object_back_instead_of_releasing_it_on_others_at_the_opening():
    positions, interventions = pick_and_place({"stacked": "put back"}, 0.05)
    (event,) = interventions
    assert event["primitive"] == "place" and event["phase"] == "land" and event["signal"] == "height"
    assert event["bottom_m"] == pytest.approx(0.06, abs=0.005)  # on the 6 cm box
    assert event["front_m"] == pytest.approx(0.02, abs=0.01)  # 5 cm less half the 6 cm box
    assert event["reaction"] == "landed on objects at the opening: put back where picked"
    assert positions[0] == pytest.approx([0.30, 0.20, 0.05], abs=0.005)  # back where it was picked
    assert positions[1] == pytest.approx([0.10, 0.0, 0.03], abs=0.003)  # the low box untouched


@pytest.mark.parametrize("watch, place_x", [
    ({"stack_front": 0.01}, 0.05),  # its front 2 cm behind the opening: not "at the opening" for this watch
    ({"stack_height": 0.07}, 0.05),  # 6 cm up counts as on the floor for this watch
    (True, 0.25),  # on the floor, deep inside
])
def test_the_place_check_releases_where_its_rule_allows(watch, place_x):
    positions, interventions = pick_and_place(watch, place_x)
    assert interventions == []
    assert positions[0, 0] != pytest.approx(0.30, abs=0.01)  # released, not put back


def test_stacked_deeper_places_the_refused_object_again_further_in():
    positions, interventions = pick_and_place(True, 0.05)  # the defaults
    (event,) = interventions
    assert event["phase"] == "land" and event["reaction"].startswith(
        "landed on objects at the opening: placed again at (")
    x, y = (float(v) for v in event["reaction"].split("(")[1].rstrip(")").split(", "))
    # released on the floor, its front edge (the 6 cm box's half width ahead of its centre) at least
    # stack_front behind the opening, where the place heuristic wants a class-1 object
    assert positions[0, 2] == pytest.approx(0.05, abs=0.005)
    assert positions[0, 0] - 0.03 >= 0.10 - 0.005
    assert positions[0, :2] == pytest.approx([x, y], abs=0.01)
    assert positions[1] == pytest.approx([0.10, 0.0, 0.03], abs=0.003)
