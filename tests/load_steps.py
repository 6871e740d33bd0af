"""The load-step model of the swing-window tests (tests/control/test_load_comp_step_*.py): a payload
put down on the IPAnema 3 at a fixed pose as the sweep puts it down (cosine over RAMP from REST), the
platform moving by a given z(t), the cable forces those of the true motion; the load compensation's
estimate (4.4) with the estimated pose's acceleration run over it."""
import numpy as np

from cdpr_control.control.load_compensation import LoadCompensation, LoadCompensationParams, payload_wrench
from cdpr_control.model.dynamics import platform_wrench
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.model.robot import load_robot

IPANEMA3 = load_robot("ipanema3")
POSE = np.r_[-1.0, -1.0, 0.5, 0.0, 0.0, 0.0]
DT = 1e-3
ESTIMATED = LoadCompensationParams(enabled=False, acceleration_source="estimated")
REST, RAMP = 0.7, 0.3            # the sweep's step: put down over 0.3 s (cosine) from 0.7 s


def forces(m_c, a_z):
    """Cable forces with -A^T(POSE) f = the wrench of the platform and a payload m_c [kg] at its
    origin (2.33) accelerating vertically by a_z [m/s²]: the forces of the true state, exact."""
    xddot = np.r_[0.0, 0.0, a_z, 0.0, 0.0, 0.0]
    w = platform_wrench(IPANEMA3, POSE, np.zeros(6), xddot) + payload_wrench(IPANEMA3, POSE, np.zeros(6), xddot,
                                                                              m_c, np.zeros(3))
    return np.linalg.pinv(inverse_kinematics(IPANEMA3, POSE).AT) @ -w


def payload(t, mass, start=REST):
    """The payload [kg] at t: ``mass`` put down over RAMP (cosine) from ``start``."""
    return mass * 0.5 * (1.0 - np.cos(np.pi * np.clip((t - start) / RAMP, 0.0, 1.0)))


def run(payload_of_t, z, duration):
    """The payload m(t) [kg], the platform moving by z(t) -> (true z, z the forward kinematics gives)
    -> (t, m_c per period, the window of (4.4) per period [s])."""
    lc = LoadCompensation(IPANEMA3, DT, ESTIMATED)
    t = np.arange(int(round(duration / DT))) * DT
    true_z, estimated_z = z(t)
    a = np.gradient(np.gradient(true_z, DT), DT)
    m_c, windows = [], []
    for k, (m, a_k) in enumerate(zip(payload_of_t(t), a)):
        x = POSE.copy()
        x[2] += estimated_z[k]
        lc.update(POSE, np.zeros(6), np.zeros(6), forces(m, a_k), x)
        m_c.append(lc.m_c)
        windows.append((lc.window_n or lc.wrench_filter.n) * DT)
    return t, np.array(m_c), np.array(windows)
