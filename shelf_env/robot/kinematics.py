"""Closed-form kinematics of the UR5 (standard DH model).

Why closed form: PyBullet's numeric IK costs ~0.7 ms a call here and does not always converge
for long straight tool paths, while a straight-line motion needs a joint target every few
millimetres. The analytic solution (Hawkins, "Analytic Inverse Kinematics for the Universal
Robots UR-5/UR-10 Arms", 2013) is exact, vectorised over whole paths, and cheap.

Frames: ``base`` is the DH base frame of the arm and ``flange`` the DH frame 6. The URDF we ship
(`assets/ur5_blade.urdf`) uses the ROS-Industrial link frames; `shelf_env.robot.arm` holds the two
fixed transforms that relate them (checked against PyBullet in the tests).
"""

from __future__ import annotations

import numpy as np

# UR5 DH parameters (Universal Robots' published table), metres / radians.
UR5_D = np.array([0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823])
UR5_A = np.array([0.0, -0.425, -0.39225, 0.0, 0.0, 0.0])
UR5_ALPHA = np.array([np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0])


def _dh(theta: np.ndarray, i: int) -> np.ndarray:
    """Homogeneous transform of DH joint ``i`` for angles ``theta`` of shape (K,) -> (K, 4, 4)."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(UR5_ALPHA[i]), np.sin(UR5_ALPHA[i])
    t = np.zeros(theta.shape + (4, 4))
    t[..., 0, 0] = ct
    t[..., 0, 1] = -st * ca
    t[..., 0, 2] = st * sa
    t[..., 0, 3] = UR5_A[i] * ct
    t[..., 1, 0] = st
    t[..., 1, 1] = ct * ca
    t[..., 1, 2] = -ct * sa
    t[..., 1, 3] = UR5_A[i] * st
    t[..., 2, 1] = sa
    t[..., 2, 2] = ca
    t[..., 2, 3] = UR5_D[i]
    t[..., 3, 3] = 1.0
    return t


def forward(q: np.ndarray) -> np.ndarray:
    """Flange pose in the DH base frame for joint angles ``q`` of shape (..., 6)."""
    q = np.asarray(q, dtype=float)
    t = _dh(q[..., 0], 0)
    for i in range(1, 6):
        t = t @ _dh(q[..., i], i)
    return t


def inverse_all(pose: np.ndarray) -> np.ndarray:
    """All 8 closed-form solutions for flange poses ``pose`` of shape (K, 4, 4) -> (K, 8, 6).

    Unreachable branches come out as NaN. Branch order: shoulder (2) x wrist (2) x elbow (2).
    """
    pose = np.asarray(pose, dtype=float)
    k = pose.shape[0]
    d4, d6 = UR5_D[3], UR5_D[5]
    a2, a3 = UR5_A[1], UR5_A[2]
    out = np.full((k, 8, 6), np.nan)
    p05 = pose[:, :3, 3] - d6 * pose[:, :3, 2]
    r = np.hypot(p05[:, 0], p05[:, 1])
    psi = np.arctan2(p05[:, 1], p05[:, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.arccos(np.clip(d4 / r, -1.0, 1.0) + np.where(r < d4, np.nan, 0.0))
        inv_pose = np.linalg.inv(pose)
        col = 0
        for s1 in (1.0, -1.0):
            t1 = psi + s1 * phi + np.pi / 2
            c1, sn1 = np.cos(t1), np.sin(t1)
            arg5 = (pose[:, 0, 3] * sn1 - pose[:, 1, 3] * c1 - d4) / d6
            arg5 = np.where(np.abs(arg5) <= 1.0 + 1e-9, np.clip(arg5, -1.0, 1.0), np.nan)
            for s5 in (1.0, -1.0):
                t5 = s5 * np.arccos(arg5)
                sn5 = np.sin(t5)
                x60, y60 = inv_pose[:, :3, 0], inv_pose[:, :3, 1]
                t6 = np.arctan2(
                    (-x60[:, 1] * sn1 + y60[:, 1] * c1) / sn5,
                    (x60[:, 0] * sn1 - y60[:, 0] * c1) / sn5,
                )
                t6 = np.where(np.abs(sn5) < 1e-9, 0.0, t6)
                t01 = _dh(t1, 0)
                t45 = _dh(t5, 4)
                t56 = _dh(t6, 5)
                t14 = np.linalg.inv(t01) @ pose @ np.linalg.inv(t45 @ t56)
                # origin of frame 3 seen from frame 1: the planar 2-link problem (Hawkins eq. for P13)
                p13 = t14 @ np.array([0.0, -d4, 0.0, 1.0])
                p13x, p13y = p13[:, 0], p13[:, 1]
                r13 = np.hypot(p13x, p13y)
                arg3 = (r13**2 - a2**2 - a3**2) / (2 * a2 * a3)
                arg3 = np.where(np.abs(arg3) <= 1.0 + 1e-9, np.clip(arg3, -1.0, 1.0), np.nan)
                for s3 in (1.0, -1.0):
                    t3 = s3 * np.arccos(arg3)
                    t2 = -np.arctan2(p13y, -p13x) + np.arcsin(a3 * np.sin(t3) / r13)
                    t12 = _dh(t2, 1)
                    t23 = _dh(t3, 2)
                    t34 = np.linalg.inv(t23) @ np.linalg.inv(t12) @ t14
                    t4 = np.arctan2(t34[:, 1, 0], t34[:, 0, 0])
                    out[:, col] = np.stack([t1, t2, t3, t4, t5, t6], axis=-1)
                    col += 1
    return out


def inverse_near(pose: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """The solution of each pose closest to ``q_ref`` (angles unwrapped towards it).

    ``pose`` (K, 4, 4), ``q_ref`` (6,) -> (K, 6). Raises ValueError for an unreachable pose,
    naming it, so a motion is never half-planned.
    """
    sols = inverse_all(pose)
    q_ref = np.asarray(q_ref, dtype=float)
    # unwrap every angle to the copy nearest the reference
    sols = q_ref + (sols - q_ref + np.pi) % (2 * np.pi) - np.pi
    dist = np.where(np.isnan(sols).any(-1), np.inf, np.abs(sols - q_ref).sum(-1))
    best = np.argmin(dist, axis=1)
    if np.isinf(dist[np.arange(len(best)), best]).any():
        bad = int(np.flatnonzero(np.isinf(dist.min(axis=1)))[0])
        raise ValueError(f"pose {bad} of the path is out of the UR5's reach: {pose[bad, :3, 3]}")
    return sols[np.arange(len(best)), best]
