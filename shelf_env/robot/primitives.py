"""The two motion primitives of §IV-B, push and pick-and-place, as the paper runs them: open loop.

`Primitives` executes them with a `shelf_env.robot.arm.Robot`: each takes poses and returns what
happened, and the env decides the next pose (e.g. the place pose from the object held). Its hooks
(`Primitives._carry_move`, `_way_out`, `_landing_check`, ...) are where a closed loop
(`shelf_env.conditions.closed_loop.WatchedPrimitives`) watches and reacts; here they just move.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.robot import kinematics
from shelf_env.robot.arm import (
    BLADE_MID_ABOVE_TCP,
    EE_IN_FLANGE,
    OUTSIDE_X_MIN,
    TCP_IN_EE,
    Robot,
    carry_height,
)


@dataclass(frozen=True)
class Grasp:
    """What a successful pick leaves in the cup: the object, where the carry stopped (in front of
    the opening, at carry height, ``lane_y`` after a detour) and where the object was picked (the
    TCP's ``x``, ``y``: the closed loop's place check puts it back there)."""

    uid: int
    out_x: float
    z_carry: float
    x: float
    y: float
    lane_y: float


class Primitives:
    """Push, pick and place (§IV-B) executed open loop by a :class:`Robot` (see the module docstring)."""

    def __init__(self, robot: Robot):
        self.robot = robot
        #: What a closed loop did during the current primitive (cleared by the caller per action;
        #: always empty in open loop).
        self.interventions: list[dict] = []

    def push(self, x: float, y: float, direction: float,
             length: float = params.PUSH_LENGTH, height: float = params.PUSH_HEIGHT) -> None:
        """Straight push: in at (x, y) with the blade's middle at ``height``, ``length`` along
        +y (``direction`` = +1, the camera's left) or -y (-1), and back out the same way."""
        r, m = self.robot, self.robot.motion
        z = height - BLADE_MID_ABOVE_TCP
        outside = np.array([m.outside_x, y, z])
        start = np.array([x, y, z])
        end = start + np.array([0.0, direction * length, 0.0])
        r.teleport(outside)
        r.move_linear(outside, start, m.approach_speed)
        r.move_linear(start, end, m.push_speed)
        r.move_linear(end, start, m.push_speed)
        r.move_linear(start, outside, m.approach_speed)
        r.go_home()

    def pick(self, x: float, y: float, surface_z: float, objects: set[int]) -> Grasp | None:
        """Descend at (x, y) from the observed surface height ``surface_z`` until the cup touches
        one of ``objects``, grip it, lift it as high as the ceiling allows and carry it out of the
        opening. Returns the `Grasp`, or None (arm back home) if the cup found nothing to grip."""
        r, m = self.robot, self.robot.motion
        self._before_pick(objects)
        z_max = carry_height(m)
        z_app = min(surface_z + m.pick_clearance, z_max)
        z_low = max(surface_z - 0.01, 0.0)
        outside = np.array([m.outside_x, y, z_app])
        above = np.array([x, y, z_app])
        r.teleport(outside)
        r.move_linear(outside, above, m.approach_speed)
        touched: list[int] = []

        def touching() -> bool:
            touched[:] = [b for b in r.cup_contacts() if b in objects]
            return bool(touched)

        r.move_linear(above, np.array([x, y, z_low]), m.vertical_speed, stop=touching, check_every=1)
        if not touched:
            touching()
        if not touched:
            here = np.array([x, y, z_low])
            r.move_linear(here, above, m.vertical_speed)
            r.move_linear(above, outside, m.approach_speed)
            r.go_home()
            return None
        obj = touched[0]
        r.grip(obj)
        here = self._commanded_tcp()
        # carry as high as the ceiling allows: a held object dragged low through the clutter in
        # front is what pushes other objects out of the opening (the paper's main failure, §V-d)
        z_carry = max(z_max, here[2])
        lifted = np.array([x, y, z_carry])
        if self._carry_move(here, lifted, m.lift_speed, "lift"):
            return None
        pick_y = y
        way_out = self._way_out(x, y, lifted, z_carry)
        if way_out is None:
            return None
        lifted, y = way_out
        # retreat until the held object is out of the opening (it hangs under the cup, so
        # only the part ahead of the TCP matters); bounded to stay within the arm's reach
        ahead = pb.getAABB(obj, physicsClientId=r.client)[1][0] - self._commanded_tcp()[0]
        out_x = float(np.clip(-ahead - 0.01, OUTSIDE_X_MIN, m.outside_x))
        if self._carry_move(lifted, np.array([out_x, y, z_carry]), m.approach_speed, "retreat"):
            return None
        return Grasp(int(obj), out_x, float(z_carry), float(x), float(pick_y), float(y))

    # ---- hooks: the open loop's (the paper's) motions; a closed loop overrides them
    def _before_pick(self, objects: set[int]) -> None:
        """Called before the arm goes in to pick among ``objects``."""

    def _carry_move(self, start: np.ndarray, end: np.ndarray, speed: float, phase: str) -> bool:
        """Move the held object (``phase``: lift, detour, retreat). True if the object is no longer held
        afterwards (a closed loop caught a drag and put it down); the open loop just moves."""
        self.robot.move_linear(start, end, speed)
        return False

    def _way_out(self, x: float, y: float, lifted: np.ndarray, z_carry: float) -> tuple[np.ndarray, float] | None:
        """Where the carry out of the opening starts after the lift at ``lifted`` (and its y), or None if
        the object was put back instead; the open loop carries straight out."""
        return lifted, y

    def _landing_check(self, obj: int, hang: float) -> Callable[[], bool] | None:
        """A check that refuses the place's landing once the lowering has stopped (None: every landing
        is released, the open loop)."""
        return None

    def _refused_landing(self, grasp: Grasp, y: float, z_release: float) -> None:
        """What happens to a held object whose landing `_landing_check` refused (never in open loop)."""
        raise AssertionError("the open loop refuses no landing")

    def place(self, grasp: Grasp, x: float, y: float) -> None:
        """Carry the held object of ``grasp`` in front of (x, y), in at carry height, lower it
        until it lands (or hangs just above the floor), release it and go home (a closed loop may
        refuse the landing, `_landing_check`, and do something else, `_refused_landing`)."""
        r, m = self.robot, self.robot.motion
        obj, out_x, z_carry = grasp.uid, grasp.out_x, grasp.z_carry
        hang = self._commanded_tcp()[2] - pb.getAABB(obj, physicsClientId=r.client)[0][2]
        r.teleport(np.array([out_x, y, z_carry]))
        r.move_linear(np.array([out_x, y, z_carry]), np.array([x, y, z_carry]), m.approach_speed)
        z_release = min(max(hang + m.release_gap, 0.0), z_carry)
        refuse = self._landing_check(obj, hang)
        if not self._lower_and_release(obj, np.array([x, y, z_carry]), np.array([x, y, z_release]), refuse):
            self._refused_landing(grasp, y, z_release)

    def _lower_and_release(self, obj: int, start: np.ndarray, low: np.ndarray,
                           refuse: Callable[[], bool] | None = None) -> bool:
        """Lower the held ``obj`` from ``start`` towards ``low`` until it touches anything but the
        tool, release it, lift the cup clear and leave the cabinet (in front of the opening) for home.
        If ``refuse`` says so once the lowering has stopped, return False instead, still holding it."""
        r, m = self.robot, self.robot.motion

        def landed() -> bool:  # the held object touches anything but the tool
            pts = pb.getContactPoints(bodyA=obj, physicsClientId=r.client)
            return any(p[2] != r.uid for p in pts)

        x, y = float(low[0]), float(low[1])
        r.move_linear(start, low, m.lift_speed, stop=landed)
        if refuse is not None and refuse():
            return False
        r.release()
        r.hold_still(12)
        here = self._commanded_tcp()
        r.move_linear(here, np.array([x, y, min(here[2] + m.lift, carry_height(m))]), m.vertical_speed)
        here = self._commanded_tcp()
        r.move_linear(here, np.array([min(m.outside_x, x), y, here[2]]), m.approach_speed)
        r.go_home()
        return True

    def _commanded_tcp(self) -> np.ndarray:
        """TCP position of the last commanded joint angles (the path the planner is on)."""
        frames = self.robot.world_from_dh @ kinematics.forward(self.robot.q_cmd[None])[0]
        ee = frames @ EE_IN_FLANGE
        return ee[:3, :3] @ TCP_IN_EE + ee[:3, 3]
