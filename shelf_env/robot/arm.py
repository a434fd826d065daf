"""The UR5 with its pushing blade and suction cup, and the two motion primitives (§IV-B).

Motion model. Every motion that enters the cabinet is simulated: the tool-centre point (TCP, the
lip of the suction cup) follows a straight line, the closed-form IK (`shelf_env.robot.kinematics`)
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

from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources

import numpy as np
import pybullet as pb

from shelf_env import params
from shelf_env.robot import kinematics
from shelf_env.world.cabinet import is_at_rest

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
        """Every other body at rest (`shelf_env.world.cabinet`'s definition, under which the env puts it to
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
