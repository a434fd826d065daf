"""Closed-form UR5 kinematics against PyBullet's own forward kinematics."""

import numpy as np
import pybullet as pb
import pytest

from shelf_env.robot import kinematics
from shelf_env.robot.arm import DH_BASE_IN_URDF, EE_IN_FLANGE, Robot
from shelf_env.world.cabinet import World


def test_inverse_reproduces_forward_on_all_branches():
    rng = np.random.default_rng(0)
    q = rng.uniform(-3, 3, (200, 6))
    poses = kinematics.forward(q)
    sols = kinematics.inverse_all(poses)
    fk = kinematics.forward(np.nan_to_num(sols.reshape(-1, 6))).reshape(200, 8, 4, 4)
    err = np.abs(fk - poses[:, None]).max((-1, -2))
    ok = ~np.isnan(sols).any(-1)
    assert ok.any(1).all()  # every pose has solutions
    assert err[ok].max() < 1e-9


def test_dh_model_matches_the_shipped_urdf():
    client = pb.connect(pb.DIRECT)
    try:
        robot = Robot(client, base_position=(0.0, 0.0, 0.0))
        rng = np.random.default_rng(1)
        for q in rng.uniform(-3, 3, (10, 6)):
            for j in range(6):
                pb.resetJointState(robot.uid, j, q[j], physicsClientId=client)
            ee = pb.getLinkState(robot.uid, robot.cup_link - 1, computeForwardKinematics=True,
                                 physicsClientId=client)
            expect = DH_BASE_IN_URDF @ kinematics.forward(q) @ EE_IN_FLANGE
            assert np.allclose(ee[4], expect[:3, 3], atol=1e-5)
            rot = np.array(pb.getMatrixFromQuaternion(ee[5])).reshape(3, 3)
            assert np.allclose(rot, expect[:3, :3], atol=1e-5)
    finally:
        pb.disconnect(client)


def test_tool_tracks_straight_lines_across_the_cabinet():
    client = pb.connect(pb.DIRECT)
    try:
        World(client)
        robot = Robot(client)
        for x, y in [(0.38, 0.28), (0.38, -0.28), (0.05, 0.0), (0.2, 0.25)]:
            start = np.array([-0.06, y, 0.015])
            robot.teleport(start)
            robot.move_linear(start, np.array([x, y, 0.015]), 0.25)
            robot.hold_still(5)
            assert np.linalg.norm(robot.tcp_position() - [x, y, 0.015]) < 0.003
            robot.go_home()
        with pytest.raises(ValueError, match="out of the UR5's reach"):
            robot.ik(np.array([2.0, 0.0, 0.0]))
    finally:
        pb.disconnect(client)
