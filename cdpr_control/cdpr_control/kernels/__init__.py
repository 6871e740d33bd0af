"""Compiled per-period numerics of the control loop (numba, cached on disk).

The controller's stages (friction compensation, forward kinematics, force set-point, CFC, OSPC,
joint command) run at 1 kHz; as numpy calls on arrays of 6 or 8 numbers they cost mostly call
overhead. This package holds the numeric cores of one period compiled with numba: the inverse
kinematics of one pose with pulleys (2.3)-(2.10), the elastic forward kinematics with frozen pulleys
(3.7)-(3.9), the platform wrench w_dyn (2.33), the Dahl friction step (3.43)-(3.44), the Smith
predictor of the wrench set-point (3.24)-(3.26), the PI arithmetic (3.16)/(3.19), the whole CFC
period (3.19)-(3.23), the joint command's period (5.10) and the force watch's per-cable period
(control.safety.ForceWatch); for the simulator, the pulley friction to
the force sensors (3.43)-(3.44) (:mod:`.friction`). The control flow and the state stay in the stage
classes (and the simulator's models), which call the functions below at their call sites.

The numpy modules (kinematics, forward_kinematics, dynamics, friction, wrench_setpoint, pi_control)
stay the readable reference: each function below is the same computation, and the tests compare the
two on random poses to a tight tolerance. ``ENABLED`` selects per call: with it False (or the
environment variable ``CDPR_KERNELS=0`` at import) every stage runs the numpy reference, e.g. to
check a suspicion against it; :func:`numpy_reference` switches it off for a block.

Compiled code is cached in ``__pycache__`` (``cache=True``): the first use on a machine (or after an
edit of a kernel's source) compiles for some tens of seconds, later processes load the cache in
about a second; :func:`warm_up` runs each kernel once so that a process pays that before its first
period, not in it. See docs/kernels.md.
"""
from __future__ import annotations

import contextlib
import os
from typing import NamedTuple

import numpy as np

# the numpy references, under names that the submodules of this package (kernels.friction) do not
# shadow
from cdpr_control.model import cable as np_cable
from cdpr_control.model import dynamics as np_dynamics
from cdpr_control.model import kinematics as np_kinematics
from cdpr_control.model.memo import Memo
from cdpr_control.kernels.control import CFC_CONSTANTS, cfc_constants
from cdpr_control.kernels.control import cfc_internal_period as _cfc_internal_period
from cdpr_control.kernels.control import cfc_period as _cfc_period
from cdpr_control.kernels.control import force_watch_period
from cdpr_control.kernels.control import internal_pi_kernel, nullspace_projector_kernel
from cdpr_control.kernels.control import pi_update as _pi_update
from cdpr_control.kernels.control import widened_saturation_kernel
from cdpr_control.kernels.friction import friction_platform_force, friction_sensor_force
from cdpr_control.kernels.model import cable_lengths as _cable_lengths
from cdpr_control.kernels.model import (_AT, _BETA, _C, _GAMMA, _KAPPA, _L_F, _Q, _ROWS, elastic_cable_state,
    elastic_frozen, ik_packed)
from cdpr_control.kernels.model import secant_stiffness
from cdpr_control.kernels.model import inverse_kinematics as _inverse_kinematics
from cdpr_control.kernels.model import joint_command_period, joint_command_step
from cdpr_control.kernels.model import measured_wrench as _measured_wrench
from cdpr_control.kernels.model import platform_wrench as _platform_wrench
from cdpr_control.kernels.robot_data import RobotData, robot_data, vector
from cdpr_control.kernels.setpoint import smith_step

ENABLED: bool = os.environ.get("CDPR_KERNELS", "1") != "0"

__all__ = ["CFC_CONSTANTS", "ENABLED", "LAWS", "Law", "RobotData", "SetpointIK", "cable_lengths", "cable_stiffness", "compiled_pi_update",
           "cfc_constants", "compiled_cfc_internal_period", "compiled_cfc_period", "compiled_internal_pi_update",
           "compiled_nullspace_projector", "compiled_joint_command_period", "compiled_widened_saturation", "elastic_cable_state", "elastic_frozen",
           "force_watch_period", "friction_platform_force", "friction_sensor_force", "inverse_kinematics", "inverse_kinematics_fields",
           "joint_command_step", "law", "measured_wrench", "numpy_reference", "platform_wrench", "robot_data", "setpoint_ik",
           "vector", "warm_up"]


class Law:
    """One computation of the thesis in two flavours: the readable numpy ``reference`` (in model/ or
    control/) and its ``compiled`` twin (numba, in this package), with the same arguments and
    results. Calling the law runs the twin while :data:`ENABLED`, else the reference: the one place
    where the project chooses between them (``CDPR_KERNELS=0``, :func:`numpy_reference`)."""

    __slots__ = ("name", "reference", "compiled")

    def __init__(self, name: str, reference, compiled):
        self.name, self.reference, self.compiled = name, reference, compiled

    def __call__(self, *args):
        return (self.compiled if ENABLED else self.reference)(*args)

    def __repr__(self) -> str:
        return f"Law({self.name!r})"


LAWS: dict[str, Law] = {}   # name -> law: every computation that has a compiled twin (docs/kernels.md)


def law(name: str, reference, compiled) -> Law:
    """Register the law ``name`` (once; a module re-imported registers the same functions again)."""
    LAWS[name] = Law(name, reference, compiled)
    return LAWS[name]


@contextlib.contextmanager
def numpy_reference():
    """Run the block on the numpy reference implementations (ENABLED False), then restore."""
    global ENABLED
    before, ENABLED = ENABLED, False
    try:
        yield
    finally:
        ENABLED = before


def _cable_stiffness(robot, f, l_t) -> np.ndarray:
    d = robot_data(robot)
    k = np.empty(np.shape(f))
    secant_stiffness(vector(f), vector(l_t), d.k0, d.k1, d.k2, k)
    return k


# the model's laws (their references in model/); the control stages register theirs beside their references
inverse_kinematics = law("inverse_kinematics", np_kinematics.inverse_kinematics, _inverse_kinematics)   # (2.3)-(2.10)
cable_lengths = law("cable_lengths", np_kinematics.cable_lengths, _cable_lengths)                        # (2.7)
measured_wrench = law("measured_wrench", np_kinematics.measured_wrench, _measured_wrench)                # (2.11)
platform_wrench = law("platform_wrench", np_dynamics.platform_wrench, _platform_wrench)                  # (2.33)
cable_stiffness = law("cable_stiffness", np_cable.stiffness, _cable_stiffness)                            # (2.15)-(2.16)


# rows of model.ik_packed's array per field of inverse_kinematics_fields (cT: the c_i as columns)
_FIELD_ROWS = {"q": _Q, "beta": _BETA, "gamma": _GAMMA, "l_f": _L_F, "kappa": _KAPPA, "AT": slice(_AT, _AT + 6),
               "cT": slice(_C, _C + 3)}


def inverse_kinematics_fields(robot, x, *names: str) -> tuple[np.ndarray, ...]:
    """The fields ``names`` (among q, beta, gamma, l_f, kappa, AT and cT = c^T) of
    :func:`inverse_kinematics` of one pose x (6,), the same numbers: a stage that needs two of them
    (the force set-point A^T, the friction beta) saves building the other ten views (about 6 us of
    its 10). They are C-contiguous rows (as the kernels take them) of an array that the next call
    for the same robot and pose returns again, the same view objects (see :func:`_packed`): read
    them, never write."""
    if ENABLED:
        P, views = _packed(robot, x)
        if P is not None:
            fields = []
            for name in names:
                view = views.get(name)
                if view is None:     # a field not asked for at this pose yet: its view, once per pose
                    view = views[name] = P[_FIELD_ROWS[name]]
                fields.append(view)
            return tuple(fields)
    ik = inverse_kinematics(robot, x)
    return tuple(ik.c.T if name == "cT" else getattr(ik, name) for name in names)


class SetpointIK(NamedTuple):
    """The fields of the IK of a period's set-point x_d (2.3)-(2.10) that its stages share:
    q (m,), A^T (6, m), c^T (3, m) (the leave points as columns) and β (m,) (:func:`setpoint_ik`);
    compiled, C-contiguous float64 rows of the packed IK as the kernels take them (on the numpy
    reference the full IK's arrays, c^T a view of its c). ControlLoop takes them once a period and hands
    them to the friction compensation (β), the forward kinematics (all four) and the force set-point
    (A^T); a node's stage takes what it needs itself (:func:`inverse_kinematics_fields`), of the
    same computation."""

    q: np.ndarray
    AT: np.ndarray
    cT: np.ndarray
    beta: np.ndarray

    @property
    def c(self) -> np.ndarray:
        """(m, 3) the leave points as rows, as :class:`cdpr_control.model.kinematics.InverseKinematics`."""
        return self.cT.T


def setpoint_ik(robot, x) -> SetpointIK:
    """The :class:`SetpointIK` of the pose x (6,): :func:`inverse_kinematics_fields` of its four fields."""
    return SetpointIK(*inverse_kinematics_fields(robot, x, "q", "AT", "cT", "beta"))


# (RobotData, packed IK, its views by field) of the last _packed call's robot constants and pose
# bytes (the RobotData kept in the value: its id cannot be taken by another while the memo holds it)
_packed_memo = Memo()


def _packed(robot, x) -> tuple[np.ndarray | None, dict]:
    """model.ik_packed of one pose (None where R does not fit its layout, m < 3) and the views of its
    fields made so far. The last result is kept and returned again for the same robot constants and
    pose: the stages of a period (friction compensation, forward kinematics, force set-point, load
    compensation, in ControlLoop and in the nodes of a composed graph alike) all take the IK of the
    period's x_d, which one computation then serves. Keyed on the :func:`robot_data`, which robots of
    equal constants share: each node of a composed graph has a robot object of its own (keyed on the
    robot, the graph's three callers at x_d computed it three times a period, session 24). Each view
    is made once per pose (a slice costs about 0.7 us, a look-up 0.1)."""
    x, d = vector(x), robot_data(robot)
    return _packed_memo((id(d), x.tobytes()), _compute_packed, d, x)[1:]


def _compute_packed(d: RobotData, x) -> tuple:
    if d.a.shape[0] < 3:
        return d, None, {}
    P = np.empty((_ROWS + 3, d.a.shape[0]))
    ik_packed(x, d.a, d.b, d.R_A, d.r_p, d.pulleys, P)
    return d, P, {}


def _per_channel(n, v) -> np.ndarray:
    """v (a scalar or (n,)) as the writeable float64 (n,) array a kernel takes."""
    return np.full(n, v, dtype=float) if np.ndim(v) == 0 else vector(v)


def compiled_pi_update(e, K_p, T_i, dt, integrator, u_neg, u_pos):
    """The compiled PI period (see :mod:`.control`) -> new arrays (integrator, saturated, output):
    the twin of control.pi_control.pi_update. Scalar limits u_neg, u_pos apply to every channel."""
    n = e.shape[0]
    if not (type(u_neg) is np.ndarray and u_neg.ndim and type(u_pos) is np.ndarray and u_pos.ndim):
        u_neg, u_pos = _per_channel(n, u_neg), _per_channel(n, u_pos)
    out = np.empty(n), np.empty(n, dtype=bool), np.empty(n)
    _pi_update(vector(e), K_p, T_i, dt, vector(integrator), vector(u_neg), vector(u_pos), *out)
    return out


def compiled_nullspace_projector(AT, held=None) -> np.ndarray:
    """The twin of control.cable_force_control.nullspace_projector (see
    :func:`.control.nullspace_projector_kernel`)."""
    AT = vector(AT)
    m = AT.shape[1]
    P = np.empty((m, m))
    nullspace_projector_kernel(AT, np.zeros(m, dtype=bool) if held is None else np.asarray(held, dtype=bool), P)
    return P


def compiled_internal_pi_update(e, K_p, T_i, dt, integrator, u_neg, u_pos, AT):
    """The compiled internal-integral PI period (see :func:`.control.internal_pi_kernel`) -> new arrays
    (integrator, saturated, output): the twin of control.cable_force_control.internal_pi_update.
    Scalar gains and limits apply to every channel. The kernel computes the projector of ``AT``
    (Gram-Schmidt on its rows) every period, in less time than a look-up of a kept one."""
    n = e.shape[0]
    out = np.empty(n), np.empty(n, dtype=bool), np.empty(n)
    internal_pi_kernel(vector(e), _per_channel(n, K_p), _per_channel(n, T_i), float(dt), vector(integrator),
                       _per_channel(n, u_neg), _per_channel(n, u_pos), vector(AT), *out)
    return out


def compiled_cfc_internal_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, AT, constants):
    """:func:`compiled_cfc_period` with the internal integral: the twin of
    control.cable_force_control.cfc_internal_period (see :func:`.control.cfc_internal_period`); AT
    (6, m) is A^T of x_d (2.10)."""
    m = f.shape[0]
    saturated, out = np.empty(m, dtype=bool), np.empty((4, m))
    _cfc_internal_period(vector(f_d), vector(f_ff), vector(f), vector(f_min), vector(f_max), vector(l_t),
                         vector(dq_0), y, vector(integrator), K_p, T_i, vector(AT), constants, saturated, out)
    return out[0], saturated, out[1], out[2], out[3]


def compiled_widened_saturation(params, f, f_min, f_max):
    """The twin of control.cable_force_control.widened_saturation."""
    m = len(f)
    f_min, f_max = _per_channel(m, f_min), _per_channel(m, f_max)   # as numpy broadcasts
    sat = np.empty(m), np.empty(m)
    widened_saturation_kernel(vector(f), f_min, f_max, float(params.F_sat_n),
                              float(params.F_sat_p), float(params.widen_band), float(params.widen_factor), *sat)
    return sat


def compiled_cfc_period(f_d, f_ff, f, f_min, f_max, l_t, dq_0, y, integrator, K_p, T_i, constants):
    """One compiled CFC period (see :mod:`.control`), the twin of
    control.cable_force_control.cfc_period -> new arrays (integrator, saturated, u, f_out, dq); the
    PT1 state y (a float64 C-contiguous array) is updated in place; ``constants`` a CFC_CONSTANTS record."""
    m = f.shape[0]
    saturated, out = np.empty(m, dtype=bool), np.empty((4, m))
    _cfc_period(vector(f_d), vector(f_ff), vector(f), vector(f_min), vector(f_max), vector(l_t), vector(dq_0), y,
                vector(integrator), K_p, T_i, constants, saturated, out)
    return out[0], saturated, out[1], out[2], out[3]


def compiled_joint_command_period(robot, x_d, offset, dq_cfc, theta_d, step: float, dt: float):
    """The twin of control.joint_command.joint_command_period: (θ_d, θ̇_d) of the next period, None
    where the target is not finite or the shapes are not one pose and m cables."""
    d = robot_data(robot)
    m = d.a.shape[0]
    x_d, offset, dq_cfc, theta_d = vector(x_d), vector(offset), vector(dq_cfc), vector(theta_d)
    if x_d.shape != (6,) or offset.shape != (6,) or dq_cfc.shape != (m,) or theta_d.shape != (m,):
        return None
    theta_next, velocity = np.empty(m), np.empty(m)
    if not joint_command_period(x_d, offset, d.a, d.b, d.R_A, d.r_p, d.pulleys, dq_cfc, theta_d, float(step),
                                float(dt), theta_next, velocity):
        return None
    return theta_next, velocity


_warm = {"robot_free": False, "robot": False}


def warm_up(robot=None) -> None:
    """Load (or, the first time on a machine, compile) the kernels with the argument types the
    control loop passes (see :func:`.robot_data.vector`), so that the first period does not.

    The stage classes call it when they are built: without a robot the robot-free kernels (PI,
    widened saturation, cable stiffness, Smith predictor), with one all of them. Once per process
    (the compiled code does not depend on the robot's values); nothing when ENABLED is False.
    """
    if not ENABLED:
        return
    f, ones = np.full(8, 100.0), np.ones(6)
    if not _warm["robot_free"]:
        compiled_pi_update(np.zeros(6), ones, ones, 1e-3, np.zeros(6), ones, ones)
        widened_saturation_kernel(f, f, f, 1.0, 1.0, 1.0, 1.0, np.empty(8), np.empty(8))
        secant_stiffness(f, f, 1.0, 0.0, 0.0, np.empty(8))
        smith_step(np.zeros((2, 6)), 0, ones, ones, np.zeros(6), 0.5, ones, np.zeros(6), np.empty(6))
        constants = cfc_constants(**dict.fromkeys(CFC_CONSTANTS.names, 1.0))
        compiled_cfc_period(f, f, f, f, f, f, f, f.copy(), f, f, f, constants)
        AT = np.hstack([np.eye(6), np.ones((6, 2))])
        compiled_cfc_internal_period(f, f, f, f, f, f, f, f.copy(), f, f, f, AT, constants)
        compiled_internal_pi_update(f, f, f, 1e-3, f, f, f, AT)
        compiled_nullspace_projector(AT, np.arange(8) < 1)
        force_watch_period(f, f, True, np.ones((3, 8)), np.zeros((4, 8)), 0.5, 1e3, np.empty(5))
        _warm["robot_free"] = True
    if robot is None or _warm["robot"]:
        return
    from cdpr_control.model.friction import PulleyFriction

    d = robot_data(robot)
    x, zero, f = vector(robot.home), np.zeros(6), np.full(robot.m, float(np.mean(robot.cable.f_min)))
    ik = _inverse_kinematics(robot, x)
    _cable_lengths(robot, x)
    joint_command_step(robot, x, f, f, 1e-3)
    compiled_joint_command_period(robot, x, zero, f, f, 1e-3, 1e-3)
    _measured_wrench(robot, x, f)
    _platform_wrench(robot, x, zero, zero)
    elastic_frozen(x, vector(ik.q), vector(ik.AT), vector(ik.c.T), vector(ik.beta), d.b, d.r_p, vector(ik.q), f,
                   d.l_0, d.k0, d.k1, d.k2, 1e-9, 30, np.empty(6))
    friction_platform_force(PulleyFriction.from_robot(robot, ik.q), f, vector(ik.q), np.zeros(robot.m), ik.beta)
    # the simulator's
    friction_sensor_force(PulleyFriction.from_robot(robot, ik.q), f, vector(ik.q), np.zeros(robot.m), ik.beta)
    _warm["robot"] = True
