"""The UR5 with its pushing blade and suction cup, and the two motion primitives (§IV-B).

Motion model. Every motion that enters the cabinet is simulated: the tool-centre point (TCP, the
lip of the suction cup) follows a straight line, the closed-form IK (`shelf_env.kinematics`)
turns the line into joint targets every centimetre, and the UR5's joint motors track them while
PyBullet steps, so the arm, blade, cup and any held object collide with the cabinet and the
objects. Motions *outside* the cabinet (home <-> the pre-approach pose in front of the opening,
and the transfer between the pick and the place pre-approach poses) are teleported: they happen
in free space in front of the cabinet, where nothing can be touched, so skipping them changes
nothing inside and saves ~60 % of the physics steps. The arm is at home (out of the camera's
view) whenever the camera captures. With ``skip_free_motion`` (``physics="fast"``, the env's
default) the same reasoning extends inside the cabinet: the parts of a motion where the arm and
what it holds stay clear of everything, and nothing else moves, are not simulated either
(`Robot.move_linear`).

Suction (as in Ravens): when the cup touches an object at the end of its descent, a fixed
constraint is created between cup and object; releasing removes it.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources

import numpy as np
import pybullet as pb

from shelf_env import kinematics, params
from shelf_env.world import is_at_rest

# Tool geometry (must match assets/ur5_blade.urdf): TCP in the ee_link frame, and heights of the
# blade relative to the TCP.
TCP_IN_EE = np.array([0.435, 0.0, -0.07])
BLADE_MID_ABOVE_TCP = 0.035
TOOL_TOP_ABOVE_TCP = 0.08
# ee_link expressed in the DH flange frame (checked against PyBullet in tests/test_robot.py).
EE_IN_FLANGE = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0, 0, 0, 1.0]])
# URDF base_link to DH base: a half turn about z.
DH_BASE_IN_URDF = np.diag([-1.0, -1.0, 1.0, 1.0])

ARM_JOINTS = 6
OUTSIDE_X_MIN = -0.10  # furthest TCP retreat in front of the opening (reach limit)
JOINT_FORCES = np.array([150.0, 150.0, 150.0, 28.0, 28.0, 28.0]) * 2.0
# Free motion (`Robot.move_linear` with ``skip_free_motion``): the arm's path is sampled every
# FREE_SAMPLE_SPACING and counts as free where every movable body is farther than FREE_MARGIN from
# the arm and what it holds (one within FREE_MARGIN - FREE_SAMPLE_SPACING / 2 of the swept arm is
# always found), and every fixed body (cabinet, ground) farther than STATIC_MARGIN: the tool
# travels 5 mm under the ceiling by design, and the cabinet's faces are planes, along which a
# straight path's distance is closest at a sampled end.
FREE_SAMPLE_SPACING = 0.005
FREE_MARGIN = 0.01
STATIC_MARGIN = 0.002
FREE_RECHECK_STEPS = 24  # on an exit, how often (physics steps) to look again whether the rest is free


@dataclass
class MotionConfig:
    """Speeds and clearances of the primitives (m/s, m)."""

    approach_speed: float = 0.25
    push_speed: float = 0.10
    vertical_speed: float = 0.05
    outside_x: float = -0.06  # TCP x of the pre-approach pose in front of the opening
    waypoint_spacing: float = 0.01
    pick_clearance: float = 0.015  # approach height above the observed surface
    lift: float = 0.015  # lift after releasing
    lift_speed: float = 0.10  # vertical speed of the carry lift and of the descent to the place pose
    ceiling_clearance: float = 0.005
    release_gap: float = 0.004  # held object's bottom above the floor when released
    suction_force: float = 60.0


class Robot:
    """UR5 + blade + suction cup in a PyBullet client."""

    def __init__(self, client: int, base_position=(-0.75, 0.0, 0.0), motion: MotionConfig | None = None,
                 skip_free_motion: bool = False):
        self.client = client
        #: Do not simulate the free parts of motions (see `move_linear`); `skipped_steps` counts them.
        self.skip_free_motion = bool(skip_free_motion)
        self.skipped_steps = 0
        self.motion = motion or MotionConfig()
        urdf = str(resources.files("shelf_env") / "assets" / "ur5_blade.urdf")
        self.uid = pb.loadURDF(urdf, basePosition=base_position, useFixedBase=True,
                               flags=pb.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client)
        names = {pb.getJointInfo(self.uid, j, physicsClientId=client)[12].decode(): j
                 for j in range(pb.getNumJoints(self.uid, physicsClientId=client))}
        self.cup_link = names["cup_link"]
        self.tcp_link = names["tcp"]
        self.joints = list(range(ARM_JOINTS))
        base = np.eye(4)
        base[:3, 3] = base_position
        self.world_from_dh = base @ DH_BASE_IN_URDF
        self.dh_from_world = np.linalg.inv(self.world_from_dh)
        # Pedestal under the base, for looks and so nothing falls through it.
        half = (0.09, 0.09, (base_position[2] - params.GROUND_Z) / 2)
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client)
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=(0.3, 0.3, 0.32, 1), physicsClientId=client)
        centre = (base_position[0], base_position[1], params.GROUND_Z + half[2])
        self.pedestal_uid = pb.createMultiBody(0, col, vis, centre, physicsClientId=client)
        # Working posture: elbow up, wrist above the tool. Every IK solution is taken nearest it.
        self.q_ref = self._posture_for(np.array([0.15, 0.0, 0.10]))
        self.q_home = np.array([self.q_ref[0], -2.6, 2.3, -1.3, self.q_ref[4], self.q_ref[5]])
        self.held: tuple[int, int] | None = None  # (object uid, constraint id)
        self.physics_steps = 0
        self.go_home()

    # ---- kinematics ----------------------------------------------------------------------
    def _flange_poses(self, tcp: np.ndarray) -> np.ndarray:
        """DH flange poses (K, 4, 4) that put the TCP at ``tcp`` (K, 3) with the tool level,
        pointing +x (into the cabinet) and the blade vertical."""
        ee = np.tile(np.eye(4), (len(tcp), 1, 1))
        ee[:, :3, 3] = tcp - TCP_IN_EE
        return self.dh_from_world @ ee @ np.linalg.inv(EE_IN_FLANGE)

    def _posture_for(self, tcp: np.ndarray) -> np.ndarray:
        sols = kinematics.inverse_all(self._flange_poses(tcp[None]))[0]
        ok = ~np.isnan(sols).any(1)
        # elbow-up branch whose forearm stays above the upper arm: largest elbow-joint height
        best, best_z = None, -np.inf
        for q in sols[ok]:
            frames = self.world_from_dh @ kinematics.forward(q[None])[0]
            elbow_z = self._elbow_height(q)
            if frames[2, 2] > -0.5 and elbow_z > best_z:
                best, best_z = q, elbow_z
        if best is None:
            raise RuntimeError("no IK solution for the working posture; check the base position")
        # keep every joint far from its +-2 pi limit: solutions are unwrapped towards this
        return (best + np.pi) % (2 * np.pi) - np.pi

    def _elbow_height(self, q: np.ndarray) -> float:
        t = kinematics._dh(np.array([q[0]]), 0) @ kinematics._dh(np.array([q[1]]), 1)
        return float((self.world_from_dh @ t[0])[2, 3])

    def ik(self, tcp: np.ndarray) -> np.ndarray:
        """Joint angles (K, 6) for TCP positions (K, 3), on the working posture's branch."""
        return kinematics.inverse_near(self._flange_poses(np.atleast_2d(tcp)), self.q_ref)

    def tcp_position(self) -> np.ndarray:
        return np.asarray(pb.getLinkState(self.uid, self.tcp_link, computeForwardKinematics=True,
                                          physicsClientId=self.client)[4])

    # ---- low-level motion ----------------------------------------------------------------
    def _reset_joints(self, q, dq=None) -> None:
        """Joint angles ``q`` and velocities ``dq`` (default 0), motors untouched."""
        dq = np.zeros(ARM_JOINTS) if dq is None else dq
        for j, angle, velocity in zip(self.joints, q, dq):
            pb.resetJointState(self.uid, j, float(angle), float(velocity), physicsClientId=self.client)

    def _set_joints(self, q: np.ndarray, dq: np.ndarray | None = None) -> None:
        """The arm at ``q`` moving at ``dq`` (default still), its motors commanded to go on so."""
        dq = np.zeros(ARM_JOINTS) if dq is None else dq
        self._reset_joints(q, dq)
        self._command(q, dq)
        self.q_cmd = np.array(q, dtype=float)

    def _command(self, q: np.ndarray, dq: np.ndarray) -> None:
        pb.setJointMotorControlArray(
            self.uid, self.joints, pb.POSITION_CONTROL, targetPositions=q, targetVelocities=dq,
            forces=JOINT_FORCES, positionGains=[0.3] * ARM_JOINTS, velocityGains=[1.0] * ARM_JOINTS,
            physicsClientId=self.client,
        )

    def step(self) -> None:
        pb.stepSimulation(physicsClientId=self.client)
        self.physics_steps += 1

    def teleport(self, tcp: np.ndarray) -> None:
        """Put the arm (and a held object) at a TCP position without simulating the way there.
        Only used outside the cabinet; see the module docstring."""
        q = self.ik(np.asarray(tcp, dtype=float))[0]
        self._put_on_path(q, np.zeros(ARM_JOINTS), np.zeros(3))

    def go_home(self) -> None:
        self._set_joints(self.q_home)

    def move_linear(self, start: np.ndarray, end: np.ndarray, speed: float,
                    stop: Callable[[], bool] | None = None, check_every: int = 2,
                    skip_free: bool = True) -> bool:
        """Move the TCP along the segment start -> end at ``speed``; True if ``stop`` fired.

        IK at waypoints ``waypoint_spacing`` apart; joint targets interpolated per physics step
        with feed-forward velocities. The step count is fixed by the segment length, so a motion
        can never run away.

        Free motion. With ``skip_free_motion`` (and ``skip_free``) the parts of the path where
        nothing can happen are not simulated: while every other body is still and no part of the
        arm or of the object it holds comes within ``FREE_MARGIN`` of another body, the arm (and
        what it holds) is put on the path, at that step's joint angles and feed-forward velocities,
        instead of being driven there. Skipped are the free start of a motion (up to the last path
        sample before anything comes near) and, without a ``stop`` rule, its free rest once the
        world is still again (checked then, against where everything is then). Everything near a
        contact is simulated as before. A ``stop`` rule must therefore only fire on contact (the
        pick's touch, the place's landing); pass ``skip_free=False`` for any other rule.
        """
        start, end = np.asarray(start, float), np.asarray(end, float)
        length = float(np.linalg.norm(end - start))
        n_steps = max(1, int(np.ceil(length / (speed * params.TIME_STEP))))
        n_way = max(2, int(np.ceil(length / self.motion.waypoint_spacing)) + 1)
        s_way = np.linspace(0.0, 1.0, n_way)
        q_way = self.ik(start + s_way[:, None] * (end - start))
        s_step = np.arange(1, n_steps + 1) / n_steps
        q_path = np.stack([np.interp(s_step, s_way, q_way[:, j]) for j in range(ARM_JOINTS)], axis=1)
        dq_path = np.gradient(q_path, params.TIME_STEP, axis=0) if n_steps > 1 else np.zeros_like(q_path)
        tcp_velocity = (end - start) / max(length, 1e-12) * speed if n_steps > 1 else np.zeros(3)
        first, last = 0, n_steps  # simulate from step `first`; from step `last` on, skip once free
        samples = np.zeros(0, dtype=int)
        if self.skip_free_motion and skip_free:
            stride = max(1, int(FREE_SAMPLE_SPACING / (speed * params.TIME_STEP)))
            samples = np.unique(np.r_[np.arange(0, n_steps, stride), n_steps - 1])
            hits = np.flatnonzero(self._near(q_path[samples]))
            if self._world_still():
                if len(hits) == 0:
                    if stop is None:
                        self._put_on_path(q_path[-1], dq_path[-1], tcp_velocity)
                        self.skipped_steps += n_steps
                        return False
                    first = int(samples[-1])  # simulate the last step, for the stop rule to look
                elif hits[0] > 0:
                    first = int(samples[hits[0] - 1]) + 1
                if first > 0:
                    self._put_on_path(q_path[first - 1], dq_path[first - 1], tcp_velocity)
                    self.skipped_steps += first
            if stop is None:
                last = int(samples[hits[-1] + 1]) if len(hits) and hits[-1] + 1 < len(samples) else 0
                last = max(last, first)
        for i in range(first, n_steps):
            if i >= last and (i - last) % FREE_RECHECK_STEPS == 0 and self._world_still() \
                    and not self._near(q_path[samples[samples >= i]]).any():
                self._put_on_path(q_path[-1], dq_path[-1], tcp_velocity)
                self.skipped_steps += n_steps - i
                return False
            self._command(q_path[i], dq_path[i])
            self.step()
            self.q_cmd = q_path[i]
            if stop is not None and i % check_every == 0 and stop():
                return True
        return False

    # ---- free motion ---------------------------------------------------------------------
    def _others(self) -> list[int]:
        """Every body in the client but the robot, its pedestal and what it holds."""
        c = self.client
        mine = (self.uid, self.pedestal_uid, self.held[0] if self.held else None)
        uids = (pb.getBodyUniqueId(i, physicsClientId=c) for i in range(pb.getNumBodies(physicsClientId=c)))
        return [u for u in uids if u not in mine]

    def _world_still(self) -> bool:
        """Every other body at rest (`shelf_env.world`'s definition, under which the env puts it to
        sleep): nothing that is not simulated while the arm keeps its distance could differ."""
        return all(is_at_rest(self.client, uid) for uid in self._others())

    def _near(self, q_samples: np.ndarray) -> np.ndarray:
        """Per joint configuration: does any part of the arm, or the object it holds, come within
        ``FREE_MARGIN`` of another body? Puts the arm (and the object) at each configuration for
        the query, and back where they were."""
        c = self.client
        out = np.zeros(len(q_samples), dtype=bool)
        if len(q_samples) == 0:
            return out
        links = range(-1, pb.getNumJoints(self.uid, physicsClientId=c))
        saved = pb.getJointStates(self.uid, self.joints, physicsClientId=c)
        held = self.held[0] if self.held else None
        if held is not None:
            rel = self._object_in_cup(held)
            held_pose = pb.getBasePositionAndOrientation(held, physicsClientId=c)
            held_velocity = pb.getBaseVelocity(held, physicsClientId=c)
        others = self._others()
        boxes = np.array([pb.getAABB(u, physicsClientId=c) for u in others]).reshape(-1, 2, 3)
        margins = [STATIC_MARGIN if pb.getDynamicsInfo(u, -1, physicsClientId=c)[0] == 0 else FREE_MARGIN
                   for u in others]
        for k, q in enumerate(q_samples):
            self._reset_joints(q)
            movers = [(self.uid, np.array([pb.getAABB(self.uid, j, physicsClientId=c) for j in links]))]
            if held is not None:
                self._follow_cup(held, rel)
                movers.append((held, np.array([pb.getAABB(held, physicsClientId=c)])))
            for uid, own in movers:  # boxes first, then exact distances for the bodies whose boxes meet
                meet = ((own[:, None, 0] - FREE_MARGIN <= boxes[None, :, 1])
                        & (own[:, None, 1] + FREE_MARGIN >= boxes[None, :, 0])).all(-1).any(0)
                if any(pb.getClosestPoints(uid, others[b], margins[b], physicsClientId=c)
                       for b in np.flatnonzero(meet)):
                    out[k] = True
                    break
        self._reset_joints([j[0] for j in saved], [j[1] for j in saved])
        if held is not None:
            pb.resetBasePositionAndOrientation(held, *held_pose, physicsClientId=c)
            pb.resetBaseVelocity(held, *held_velocity, physicsClientId=c)
        return out

    def _follow_cup(self, obj: int, rel: tuple[tuple, tuple]) -> None:
        """Put body ``obj`` at pose ``rel`` in the cup's frame (where it hangs when held)."""
        cup_pos, cup_orn = pb.getLinkState(self.uid, self.cup_link, computeForwardKinematics=True,
                                           physicsClientId=self.client)[:2]
        pb.resetBasePositionAndOrientation(obj, *pb.multiplyTransforms(cup_pos, cup_orn, *rel),
                                           physicsClientId=self.client)

    def _put_on_path(self, q: np.ndarray, dq: np.ndarray, tcp_velocity: np.ndarray) -> None:
        """The arm at ``q`` moving at ``dq`` (and what it holds, moving with the TCP at
        ``tcp_velocity``), commanded to go on with that motion, as if driven there."""
        if self.held is None:
            self._set_joints(q, dq)
            return
        obj = self.held[0]
        rel = self._object_in_cup(obj)
        self._set_joints(q, dq)
        self._follow_cup(obj, rel)
        pb.resetBaseVelocity(obj, tuple(tcp_velocity), (0, 0, 0), physicsClientId=self.client)

    def hold_still(self, steps: int) -> None:
        self._command(self.q_cmd, np.zeros(ARM_JOINTS))
        for _ in range(steps):
            self.step()

    # ---- suction -------------------------------------------------------------------------
    def cup_contacts(self, exclude: set[int] | None = None) -> list[int]:
        """Bodies touching the suction cup."""
        pts = pb.getContactPoints(bodyA=self.uid, linkIndexA=self.cup_link, physicsClientId=self.client)
        return [p[2] for p in pts if exclude is None or p[2] not in exclude]

    def _object_in_cup(self, obj: int) -> tuple[tuple, tuple]:
        """Pose (position, quaternion) of body ``obj`` in the cup link's frame."""
        cup_pos, cup_orn = pb.getLinkState(self.uid, self.cup_link, computeForwardKinematics=True,
                                           physicsClientId=self.client)[:2]
        obj_pos, obj_orn = pb.getBasePositionAndOrientation(obj, physicsClientId=self.client)
        inv_pos, inv_orn = pb.invertTransform(cup_pos, cup_orn)
        return pb.multiplyTransforms(inv_pos, inv_orn, obj_pos, obj_orn)

    def grip(self, obj: int) -> None:
        rel_pos, rel_orn = self._object_in_cup(obj)
        cid = pb.createConstraint(self.uid, self.cup_link, obj, -1, pb.JOINT_FIXED, (0, 0, 0),
                                  rel_pos, (0, 0, 0), rel_orn, (0, 0, 0, 1), physicsClientId=self.client)
        pb.changeConstraint(cid, maxForce=self.motion.suction_force, physicsClientId=self.client)
        self.held = (obj, cid)

    def cup_force(self) -> np.ndarray:
        """The force (N, 3) the suction cup's sensor reads on the held object (zeros if none)."""
        if self.held is None:
            return np.zeros(3)
        return np.asarray(pb.getConstraintState(self.held[1], physicsClientId=self.client)[:3], dtype=float)

    def release(self) -> None:
        if self.held is not None:
            pb.removeConstraint(self.held[1], physicsClientId=self.client)
            self.held = None


def carry_height(motion: MotionConfig) -> float:
    """Highest TCP height that keeps the tool under the cabinet ceiling: where the pick carries."""
    return params.CABINET_HEIGHT - TOOL_TOP_ABOVE_TCP - motion.ceiling_clearance


#: What the lane check (`DragWatch.lane`) does when no way out is clear.
BLOCKED_REACTIONS = ("carry", "put back")
#: What the place check (`DragWatch.place_check`) does with a refused landing (`DragWatch.stacked`).
STACKED_REACTIONS = ("deeper", "put back")


@dataclass(frozen=True)
class DragWatch:
    """Closed-loop watch of a carried object (``ShelfSortEnv(closed_loop=True)``, or a dict of these
    fields, or a DragWatch).

    Signals a real robot has, no object poses: a look at the carry's way out before it starts, two
    watches during it, and where the place's descent stopped.

    - **Lane** (``lane``): after the lift, before the carry out, the camera's heightmap (the
      observation the policy acted on: object cells and their heights) says whether the object,
      hanging under the cup at carry height, clears every visible neighbour between it and the
      opening (`shelf_env.clearance.carry_path`; straight out exactly where
      `shelf_env.clearance.carry_clear` says so). If not, the nearest sideways shift up to
      ``detour_max`` m whose sideways carry (at carry height) and way out are both clear is taken:
      the object is carried sideways, then out. If none is, ``blocked`` says what happens:
      ``"put back"`` lowers it where it was picked (the step ends with nothing moved) and
      ``"carry"`` carries it straight out, watched as below. Most falls the two watches below still
      let through are rams: the carried object hits a taller neighbour near the opening, the sensor
      reads 5-30 N within a few millimetres, and the neighbour is already tipping out when the
      carry stops (`results/closed_loop_seed0/on/falls.md`: 44 of 61 objects that left during a
      pick left after such a catch). Looking first avoids the ram instead of catching it.

    - **Force** (``force``): the force on the suction cup (a 6-axis force sensor between wrist and
      cup on a real robot; here the suction constraint's force). While the cup carries an object
      out of the cabinet, the only horizontal force on it should be the motion's own inertia: short
      spikes at waypoint changes (≤ 0.16 N for 1-2 physics steps with a 0.3 kg box). An object that
      drags a neighbour feels the neighbour's friction steadily (0.35 to 0.48 N for a 0.15 kg box on
      wood, on the crafted scene of tests/test_closed_loop.py); one that rams a neighbour reads
      5-30 N. Each move starts with the arm jumping to its speed, which the sensor reads as up to
      ~23 N for a few steps: the first ``blank`` steps of a move are not judged. Rule: after that, a
      force component against the move's horizontal direction above ``threshold`` N for ``sustain``
      consecutive physics steps is a drag (vertical moves, the lift, cannot drag anything out of
      the opening and are not judged). With ``judge_outside=False`` it is not judged once the
      commanded TCP is in front of the opening (there the held object's own exit reads 0.5-0.9 N).
    - **Camera** (``camera_every``): the side-view camera at a quarter of its resolution (~3 ms a
      frame), every ``camera_every`` physics steps (8: 30 frames per second). Before the arm goes in,
      the front edge (smallest x of the visible points, `HeightmapCamera.front_edges`) of every
      object; during the move, an object that was ahead of the held one and whose front edge has
      come more than ``camera_shift`` m closer to the opening has been moved towards it. Occlusion by
      the arm can only hide points, never bring an edge closer. It sees little in practice: a
      dragged neighbour is mostly hidden under the carried object (tests/test_closed_loop.py: seen
      3.4 cm late).

    - **Place check** (``place_check``): the place lowers the held object until it touches
      something. Where the descent stopped (the commanded TCP height less the object's hang under
      the cup) tells the robot whether the object landed on the floor or on other objects; with the
      grasp's offset it also knows where the object's front edge is. A landing more than
      ``stack_height`` m above the floor with the front edge less than ``stack_front`` m behind the
      opening is refused: the object is not released. ``stacked`` says what happens instead:
      ``"put back"`` lifts it, carries it out the way it came, in again along the lane its pick
      carried it out, and puts it down where it was picked; ``"deeper"`` lifts it and places it
      again where the place heuristic puts it with its front edge at least ``stack_front`` behind
      the opening (on the same observation; put back where the region has no such place). Why: with the
      lane check, most objects that still left the cabinet were the held object at the place (26 of
      38, `results/closed_loop_seed0/on_lane_pb/falls.md`). Replayed, all 26 had been placed by the
      place heuristic's fallback for a full region (no free footprint: the least covered one, which
      is near the opening), landed on other objects and slid out forwards after the release. Of
      H-a's 19 landings on other objects in seed 0's 30 scenes at N = 8 (an ad-hoc replay), the 4
      that fell had their front edge within 2 cm of the opening and none behind 5.5 cm fell; fallen
      ones in the 26 had it up to ~8.5 cm behind: hence 0.10 m.

    Reaction to a drag the watches catch: stop, carry the object back ``back_off`` m along the path
    it came (free a moment ago; the default 1 m is the whole way, so it is put back where it was
    picked), lower it straight down until something carries it (a contact pushing it up), release
    it, lift the cup to carry height (where it touches nothing) and go home; the step then ends as
    usual, with the event in ``info["interventions"]``. Putting the object down where it was caught instead
    (``back_off=0.02``) dropped the neighbour it had pushed while being lowered onto it (4 of H-d's 5
    falls after an intervention at N = 8).

    Measured (``bash scripts/closed_loop_seed0.sh``, `results/closed_loop_seed0/table.md`: H-a and
    H-d on seed 0's 30 YCB scenes per N, one machine; episodes with a fall at N = 8..14 and sorted
    episodes at N = 3..5, of 60, against open loop):

    - these defaults (folder ``on_deeper``): falls -85 % (H-a) and -82 % (H-d), sorted +2 and +4;
      sorted over N = 3..14 (5 N) 67 and 70 of 150, open loop 64 and 66; with the env's
      ``safe_picks=True`` too (``on_deeper_safe``, no pick is put back): falls -78 % / -63 %,
      sorted +4 / +8, over N = 3..14 74 / 79 of 150;
    - ``stacked="put back"`` (``on_place``): falls -95 % / -93 %, sorted +1 / +3, but over N = 3..14
      60 / 63 of 150: a heuristic that picks the put-back object again loops until the time-out;
    - no place check (``place_check=False``, ``on_lane_pb``): falls -65 % / -72 %, sorted +3 / +4;
      sorted at N = 8 13 -> 9 (H-a) and 12 -> 7 (H-d) of 30, loops again;
    - ``lane`` with ``blocked="carry"`` and no place check (``on_lane``): falls -36 % / -21 %,
      sorted +6 / +7;
    - no lane and no place check (``on``): falls -27 % / -22 %, sorted +4 / +3;
      ``{"sustain": 2, "threshold": 0.5, "judge_outside": False}`` (``on_s2in``): -38 % / -45 %,
      sorted +5 / -2.
    """

    threshold: float = 0.25
    sustain: int = 6
    blank: int = 24  # physics steps ignored at the start of each move (0.1 s): the arm accelerating
    force: bool = True  # judge the cup's force sensor
    camera_every: int = 8  # physics steps between camera frames (240 Hz / 8 = 30 fps); 0: no camera check
    camera_shift: float = 0.01  # metres an object's front may come towards the opening before it is a drag
    back_off: float = 1.0  # metres carried back before the put-down (1 m: the whole way, where it was picked)
    speed_scale: float = 1.0  # watched moves run at this fraction of their open-loop speed
    judge_outside: bool = True  # judge the force also once the cup is out of the opening (TCP x < 0)
    lane: bool = True  # before the retreat, check the carry's way out in the camera's heightmap
    detour_max: float = 0.2  # metres the lane check may shift the carry sideways to find a clear way out
    blocked: str = "put back"  # no clear way out: "put back" (where picked) or "carry" (straight, watched)
    place_check: bool = True  # refuse a place landing on other objects at the opening (put back instead)
    stack_height: float = 0.02  # metres above the floor the held object's bottom may land and count as on the floor
    stack_front: float = 0.10  # metres behind the opening within which a landing on other objects is refused
    stacked: str = "deeper"  # a refused landing: "deeper" (placed again further in) or "put back" (where picked)

    def __post_init__(self) -> None:
        for name in ("threshold", "camera_shift", "back_off", "detour_max", "stack_height", "stack_front"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < float("inf"):
                raise ValueError(f"DragWatch.{name} must be a finite number >= 0, got {value!r}")
        for name in ("sustain", "blank", "camera_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"DragWatch.{name} must be an integer >= 0, got {value!r}")
        if self.sustain < 1:
            raise ValueError(f"DragWatch.sustain must be >= 1, got {self.sustain}")
        if self.blocked not in BLOCKED_REACTIONS:
            raise ValueError(f"DragWatch.blocked must be one of {BLOCKED_REACTIONS}, got {self.blocked!r}")
        if self.stacked not in STACKED_REACTIONS:
            raise ValueError(f"DragWatch.stacked must be one of {STACKED_REACTIONS}, got {self.stacked!r}")
        for name in ("force", "judge_outside", "lane", "place_check"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"DragWatch.{name} must be True or False, got {getattr(self, name)!r}")
        if isinstance(self.speed_scale, bool) or not isinstance(self.speed_scale, (int, float)) \
                or not 0 < self.speed_scale <= 1:
            raise ValueError(f"DragWatch.speed_scale must be in (0, 1], got {self.speed_scale!r}")

    @classmethod
    def from_any(cls, value: bool | dict | DragWatch) -> DragWatch | None:
        """The watch of the env's ``closed_loop`` argument: False -> None (open loop), True -> the
        defaults, a dict -> those fields changed (unknown keys are a ValueError), a DragWatch as is."""
        if isinstance(value, DragWatch):
            return value
        if isinstance(value, bool):
            return cls() if value else None
        if not isinstance(value, dict):
            raise ValueError(f"closed_loop must be True, False, a dict of DragWatch fields or a DragWatch, "
                             f"got {value!r}")
        known = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ValueError(f"unknown closed_loop keys {unknown}; known: {known}")
        return cls(**value)


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
    """Push, pick and place (§IV-B) executed by a :class:`Robot`; each takes poses and returns
    what happened, and the env decides the next pose (e.g. the place pose from the object held)."""

    def __init__(self, robot: Robot, watch: DragWatch | None = None,
                 look: Callable[[list[int]], dict[int, float]] | None = None):
        self.robot = robot
        self.watch = watch
        #: The closed loop's camera check: the front edge (smallest x) of each visible object of
        #: the given uids (`shelf_env.camera.HeightmapCamera.front_edges`); None: no camera check.
        self.look = look
        #: The camera check's reference (set by `pick` before the arm goes in, when nothing but
        #: the objects themselves hides them): each visible object's front edge.
        self._front_before: dict[int, float] = {}
        #: What the closed loop did during the current primitive (cleared by the caller per action).
        self.interventions: list[dict] = []
        #: The lane check (`DragWatch.lane`): for a pick at (x, y), the sideways shift in metres
        #: (along y) of the nearest carry out of the opening that clears every visible neighbour,
        #: 0.0 for straight out, None when none is clear (set by the env from its heightmap).
        self.plan_carry: Callable[[float, float], float | None] | None = None
        #: The place check's ``stacked="deeper"`` (`DragWatch.stacked`): for the held object's uid,
        #: the tool (x, y) where the place heuristic puts it with its front edge ``stack_front``
        #: behind the opening, None where the region allows none (set by the env).
        self.plan_place: Callable[[int], tuple[float, float] | None] | None = None

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
        if self.watch is not None and self.look is not None and self.watch.camera_every > 0:
            self._front_before = self.look(sorted(objects))
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
        if self._watched_move(here, lifted, m.lift_speed, "lift"):
            return None
        pick_y = y
        if self.watch is not None and self.watch.lane and self.plan_carry is not None:
            shift = self.plan_carry(x, y)
            event = {"primitive": "pick", "phase": "lane", "signal": "lane",
                     "tcp": [round(float(v), 4) for v in lifted]}
            if shift is None and self.watch.blocked == "put back":
                self._put_down_here(lifted)
                self.interventions.append({**event, "reaction": "no clear way out: put back where picked"})
                return None
            if shift:  # the nearest clear way out is beside this one: carry sideways first
                aside = np.array([x, y + shift, z_carry])
                self.interventions.append({**event, "reaction": f"carried {shift:+.3f} m sideways, then out"})
                if self._watched_move(lifted, aside, m.approach_speed, "detour"):
                    return None
                lifted, y = aside, y + shift
        # retreat until the held object is out of the opening (it hangs under the cup, so
        # only the part ahead of the TCP matters); bounded to stay within the arm's reach
        ahead = pb.getAABB(obj, physicsClientId=r.client)[1][0] - self._commanded_tcp()[0]
        out_x = float(np.clip(-ahead - 0.01, OUTSIDE_X_MIN, m.outside_x))
        if self._watched_move(lifted, np.array([out_x, y, z_carry]), m.approach_speed, "retreat"):
            return None
        return Grasp(int(obj), out_x, float(z_carry), float(x), float(pick_y), float(y))

    def _watched_move(self, start: np.ndarray, end: np.ndarray, speed: float, phase: str) -> bool:
        """Move the held object; with a `DragWatch`, stop on a drag (its force or camera rule), carry
        the object back and put it down (`_put_down_here`). True if that happened (the object is no
        longer held)."""
        r = self.robot
        if self.watch is None or r.held is None:
            r.move_linear(start, end, speed)
            return False
        watch, run, peak, steps = self.watch, [0], [0.0], [0]
        heading = np.asarray(end[:2], float) - np.asarray(start[:2], float)
        if np.linalg.norm(heading) < 1e-9:  # a vertical move cannot drag anything out of the opening
            r.move_linear(start, end, speed)
            return False
        heading /= np.linalg.norm(heading)
        # objects whose front was ahead of the held object's (those the carry can push out); the
        # ones behind it may show more of themselves once it has gone, which is not a motion
        held_front = self._front_before.get(r.held[0], np.inf)
        reference = {u: x for u, x in self._front_before.items() if u != r.held[0] and x < held_front}
        others = sorted(reference)
        look = self.look if watch.camera_every > 0 and others else None
        moved: list[tuple[int, float]] = []

        def dragging() -> bool:
            steps[0] += 1
            if look is not None and steps[0] % watch.camera_every == 0:
                front = look(others)
                moved[:] = [(u, reference[u] - x) for u, x in front.items()
                            if u in reference and x < reference[u] - watch.camera_shift]
                if moved:
                    return True
            if not watch.force or steps[0] <= watch.blank:
                return False
            if not watch.judge_outside and self._commanded_tcp()[0] < 0:
                run[0] = 0
                return False
            force = float(np.dot(r.cup_force()[:2], -heading))  # the part that holds the motion back
            run[0] = run[0] + 1 if force > watch.threshold else 0
            peak[0] = max(peak[0], force) if run[0] else peak[0]
            return run[0] >= watch.sustain

        if not r.move_linear(start, end, speed * watch.speed_scale, stop=dragging, check_every=1, skip_free=False):
            return False
        event: dict = {"primitive": "pick", "phase": phase,
                       "tcp": [round(float(v), 4) for v in self._commanded_tcp()]}
        if moved:
            uid, shift = max(moved, key=lambda item: item[1])
            event.update(signal="camera", object=int(uid), shift_m=round(float(shift), 4))
        else:
            event.update(signal="force", force_n=round(peak[0], 3))
        event["reaction"] = f"carried back {self._put_down_here(start):.3f} m, put down"
        self.interventions.append(event)
        return True

    def _put_down_here(self, start: np.ndarray) -> float:
        """Carry the held object back ``back_off`` along the path it came (from ``start``, free a
        moment ago: off whatever it pressed on), lower it straight down until it rests on something,
        release it, lift the cup to carry height and go home. Returns how far it was carried back.

        Not `_lower_and_release` with another landing rule: its lift and exit start from other
        (equal up to float noise) points, and the committed closed-loop results reproduce bit for
        bit only along this path."""
        r, m = self.robot, self.robot.motion
        assert r.held is not None and self.watch is not None
        obj = r.held[0]
        here = self._commanded_tcp()
        way_back = np.asarray(start, float) - here
        way_back[2] = 0.0
        if np.linalg.norm(way_back) > self.watch.back_off:
            way_back *= self.watch.back_off / np.linalg.norm(way_back)
        if np.linalg.norm(way_back) > 1e-6:
            r.move_linear(here, here + way_back, m.approach_speed / 2)
            here = here + way_back
        hang = here[2] - pb.getAABB(obj, physicsClientId=r.client)[0][2]
        low = np.array([here[0], here[1], min(max(hang + m.release_gap, 0.0), here[2])])

        def resting() -> bool:  # something under the held object carries it (contact normal upwards)
            pts = pb.getContactPoints(bodyA=obj, physicsClientId=r.client)
            return any(p[2] != r.uid and p[7][2] > 0.5 for p in pts)

        r.move_linear(here, low, m.lift_speed, stop=resting)
        r.release()
        r.hold_still(12)
        here = self._commanded_tcp()
        top = np.array([here[0], here[1], max(here[2], carry_height(m))])
        r.move_linear(here, top, m.vertical_speed)
        r.move_linear(top, np.array([min(m.outside_x, top[0]), top[1], top[2]]), m.approach_speed)
        r.go_home()
        return float(np.linalg.norm(way_back))

    def place(self, grasp: Grasp, x: float, y: float) -> None:
        """Carry the held object of ``grasp`` in front of (x, y), in at carry height, lower it
        until it lands (or hangs just above the floor), release it and go home. With the closed
        loop's place check (`DragWatch.place_check`) a landing on other objects at the opening is
        not released: the object is placed again further in or put back (`DragWatch.stacked`)."""
        r, m = self.robot, self.robot.motion
        obj, out_x, z_carry = grasp.uid, grasp.out_x, grasp.z_carry
        hang = self._commanded_tcp()[2] - pb.getAABB(obj, physicsClientId=r.client)[0][2]
        r.teleport(np.array([out_x, y, z_carry]))
        r.move_linear(np.array([out_x, y, z_carry]), np.array([x, y, z_carry]), m.approach_speed)
        z_release = min(max(hang + m.release_gap, 0.0), z_carry)
        refuse = None
        if self.watch is not None and self.watch.place_check:
            # the held object's front edge relative to the cup (it hangs rigidly under it)
            behind = pb.getAABB(obj, physicsClientId=r.client)[0][0] - self._commanded_tcp()[0]
            refuse = functools.partial(self._landed_on_others, hang, behind)
        if self._lower_and_release(obj, np.array([x, y, z_carry]), np.array([x, y, z_release]), refuse):
            return
        assert self.watch is not None
        deeper = self.plan_place(obj) if self.watch.stacked == "deeper" and self.plan_place is not None else None
        if deeper is None:
            self._put_back(grasp, y)
            self.interventions[-1]["reaction"] = "landed on objects at the opening: put back where picked"
            return
        # lift it, carry it over to the deeper place at carry height and place it there
        here = self._commanded_tcp()
        top = np.array([here[0], here[1], z_carry])
        r.move_linear(here, top, m.vertical_speed)
        start = np.array([deeper[0], deeper[1], z_carry])
        r.move_linear(top, start, m.approach_speed)
        self.interventions[-1]["reaction"] = (f"landed on objects at the opening: placed again at "
                                              f"({deeper[0]:.3f}, {deeper[1]:.3f})")
        self._lower_and_release(obj, start, np.array([deeper[0], deeper[1], z_release]))

    def _landed_on_others(self, hang: float, behind: float) -> bool:
        """The place check (`DragWatch.place_check`), when the lowering has stopped: the held object's
        bottom (the commanded TCP height less the hang) is more than ``stack_height`` above the floor,
        so it rests on other objects, and its front edge is less than ``stack_front`` behind the
        opening. Records the intervention (its reaction is the caller's) when it refuses the landing."""
        assert self.watch is not None
        tcp = self._commanded_tcp()
        bottom, front = float(tcp[2] - hang), float(tcp[0] + behind)
        if bottom <= self.watch.stack_height or front >= self.watch.stack_front:
            return False
        self.interventions.append({
            "primitive": "place", "phase": "land", "signal": "height", "bottom_m": round(bottom, 4),
            "front_m": round(front, 4), "tcp": [round(float(v), 4) for v in tcp]})
        return True

    def _put_back(self, grasp: Grasp, y: float) -> None:
        """The place check's ``stacked="put back"``: lift the still-held object to carry height, carry it out the
        way it came in (at ``y``), in again along the lane its pick carried it out (free then), over
        the spot where it was picked, and put it down there (`_put_down_here`)."""
        r, m = self.robot, self.robot.motion
        here = self._commanded_tcp()
        top = np.array([here[0], here[1], grasp.z_carry])
        r.move_linear(here, top, m.vertical_speed)
        outside = np.array([grasp.out_x, y, grasp.z_carry])
        r.move_linear(top, outside, m.approach_speed)
        lane = np.array([grasp.out_x, grasp.lane_y, grasp.z_carry])
        r.teleport(lane)
        inside = np.array([grasp.x, grasp.lane_y, grasp.z_carry])
        r.move_linear(lane, inside, m.approach_speed)
        if grasp.lane_y != grasp.y:
            above = np.array([grasp.x, grasp.y, grasp.z_carry])
            r.move_linear(inside, above, m.approach_speed)
            inside = above
        self._put_down_here(inside)

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
