"""The platform as a pybullet rigid body, described in the thesis' platform frame.

pybullet keeps a body at its centre of mass with the principal axes of inertia (the body's
"inertial frame"); the library works with the platform frame of (2.1): origin r, Kardan rotation
R, centre of gravity c and inertia J_c in that frame (robot.platform). This module converts
between the two: R_I = R V (V: principal axes in the platform frame), r_I = r + R c,
v_I = v + omega x R c. Gravity comes from pybullet (robot.gravity).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from cdpr_control.model.kinematics import cross, rotation_matrix


def kardan_angles(R: np.ndarray) -> np.ndarray:
    """[a, b, c] with R = Rx(a) Ry(b) Rz(c) (section 2.1.1), b in [-pi/2, pi/2]."""
    (r00, r01, r02), (_, _, r12), (_, _, r22) = R.tolist()
    return np.array([math.atan2(-r12, r22), math.asin(max(-1.0, min(1.0, r02))), math.atan2(-r01, r00)])


def principal_axes(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(moments (3,), V (3, 3)) with inertia = V diag(moments) V^T and det V = +1 (V = I if diagonal)."""
    inertia = np.asarray(inertia, dtype=float)
    if not np.any(inertia - np.diag(np.diag(inertia))):
        return np.diag(inertia).copy(), np.eye(3)
    moments, V = np.linalg.eigh(inertia)
    if np.linalg.det(V) < 0.0:
        V[:, 2] = -V[:, 2]
    return moments, V


class PlatformBody:
    """One pybullet body carrying the platform's mass properties (robot.platform)."""

    def __init__(self, pb, client: int, collision_shape: int, platform, x, xdot):
        self.pb = pb
        self.client = client
        self.collision_shape = collision_shape
        self.body = None
        self.set_mass_properties(platform, x, xdot)

    def set_mass_properties(self, platform, x=None, xdot=None) -> None:
        """(Re)build the body for new mass properties, keeping (or setting) pose x and twist xdot."""
        if self.body is not None:
            if x is None:
                x, xdot = self.pose_and_twist()
            self.pb.removeBody(self.body, physicsClientId=self.client)
        moments, V = principal_axes(platform.inertia)
        self.c = np.array(platform.center_of_gravity, dtype=float)
        self.V = V
        self.mass = float(platform.mass)
        self.inertia = np.ascontiguousarray(platform.inertia, dtype=float)   # about the c.o.g., platform frame
        self._offset = bool(np.any(self.c != 0.0) or np.any(V != np.eye(3)))
        pb, cid = self.pb, self.client
        self.body = pb.createMultiBody(
            self.mass, self.collision_shape,
            baseInertialFramePosition=self.c.tolist(),
            baseInertialFrameOrientation=list(Rotation.from_matrix(V).as_quat()),
            physicsClientId=cid)
        pb.changeDynamics(self.body, -1, localInertiaDiagonal=moments.tolist(), linearDamping=0.0,
                          angularDamping=0.0, lateralFriction=1.0, restitution=0.0,
                          activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=cid)
        self.set_state(x, xdot)

    def set_state(self, x, xdot) -> None:
        """Put the platform origin at pose x (6,) with twist xdot = [v; omega] (6,)."""
        x = np.asarray(x, dtype=float)
        xdot = np.zeros(6) if xdot is None else np.asarray(xdot, dtype=float)
        R = rotation_matrix(x[3:])
        Rc = R @ self.c
        r_I = x[:3] + Rc
        v_I = xdot[:3] + cross(xdot[3:], Rc)
        quat = Rotation.from_matrix(R @ self.V).as_quat()
        self.pb.resetBasePositionAndOrientation(self.body, r_I.tolist(), list(quat), physicsClientId=self.client)
        self.pb.resetBaseVelocity(self.body, v_I.tolist(), xdot[3:].tolist(), physicsClientId=self.client)

    def state(self):
        """(r (3,), R (3, 3), v (3,), omega (3,)) of the platform origin, base frame."""
        pb, body, cid = self.pb, self.body, self.client
        pos, quat = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        lin, ang = pb.getBaseVelocity(body, physicsClientId=cid)
        R = np.array(pb.getMatrixFromQuaternion(quat)).reshape(3, 3)
        r, v, omega = np.array(pos), np.array(lin), np.array(ang)
        if self._offset:
            R = R @ self.V.T
            Rc = R @ self.c
            r = r - Rc
            v = v - cross(omega, Rc)
        return r, R, v, omega

    def raw_state(self):
        """The numbers of :meth:`state` as pybullet returns them, for a compiled caller: (r (3,),
        R (9,) row by row, v (3,), omega (3,)) as tuples of floats."""
        if self._offset:
            r, R, v, omega = self.state()
            return tuple(r.tolist()), tuple(R.ravel().tolist()), tuple(v.tolist()), tuple(omega.tolist())
        pb, body, cid = self.pb, self.body, self.client
        pos, quat = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        lin, ang = pb.getBaseVelocity(body, physicsClientId=cid)
        return pos, pb.getMatrixFromQuaternion(quat), lin, ang

    def pose_and_twist(self) -> tuple[np.ndarray, np.ndarray]:
        r, R, v, omega = self.state()
        return np.concatenate([r, kardan_angles(R)]), np.concatenate([v, omega])

    def apply(self, F, T, r) -> None:
        """Apply force F and torque T about the platform origin r (base frame) for the next step."""
        pb = self.pb
        pb.applyExternalForce(self.body, -1, F.tolist(), r.tolist(), pb.WORLD_FRAME, physicsClientId=self.client)
        pb.applyExternalTorque(self.body, -1, T.tolist(), pb.WORLD_FRAME, physicsClientId=self.client)

    def apply_wrench(self, FT, r) -> None:
        """:meth:`apply` of the wrench FT = [F; T] (6,) about the platform origin r (base frame)."""
        self.apply(FT[:3], FT[3:], r)