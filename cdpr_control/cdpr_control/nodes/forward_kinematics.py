"""Node ``forward_kinematics``: elastic forward kinematics (3.7)-(3.9) and the wrench w = -A^T f (2.11).

Subscribes ``winch/state`` (θ), ``cable_forces`` (f at the platform) and ``setpoint`` (x_d, the
warm start and the pose of the frozen pulley model of section 3.2); publishes ``platform/pose``
(PoseStamped, x), ``platform/wrench`` (WrenchStamped, w about the platform origin, base frame) and
``forward_kinematics/diagnostics``. The elongation Δq_0 of the encoder calibration (3.7) comes from
the home calibration (``home_forces``) or, without one, the mean of the first
``calibration_window`` measured forces (:mod:`cdpr_control.model.calibration`). A solve that does not
converge is published with ``converged = false`` (and reported on /diagnostics); the pose message
then carries the last converged estimate. ``load_compensation/settlement`` (JointState, position = s
[m] per cable), published by the load compensation only where its settlement ratio was identified,
lengthens the FK's cables from the next period on (section 4.1.3; PoseEstimator.settlement, as
ControlLoop hands it). The computation is
:class:`cdpr_control.control.pose_estimator.PoseEstimator`.
"""
from __future__ import annotations

import inspect
import time

import numpy as np
from cdpr_msgs.msg import CableForces, ForwardKinematicsDiagnostics, OperationalSetpoint
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, WrenchStamped
from sensor_msgs.msg import JointState

from cdpr_control.model import forward_kinematics as fk
from cdpr_control.control.pose_estimator import PoseEstimator
from cdpr_control.control.safety import all_finite
from cdpr_control.ros.message_builders import builder

from cdpr_control.ros.base import CdprNode, spin_node
from cdpr_control.ros.conversions import pose_to_msg, setpoint_pose, wrench_to_msg
from cdpr_control.ros.parameters import ParameterSet, ParamSpec, calibration_params, startup_calibration
from cdpr_control.ros.qos import CONTROL
from cdpr_control.ros.sync import StampSync

TERMINATION = {
    fk.CONVERGED: ForwardKinematicsDiagnostics.CONVERGED,
    fk.MAX_ITERATIONS: ForwardKinematicsDiagnostics.MAX_ITERATIONS,
    fk.STALLED: ForwardKinematicsDiagnostics.STALLED,
    fk.NON_FINITE: ForwardKinematicsDiagnostics.INVALID_INPUT,
}

_D = {k: v.default for k, v in inspect.signature(PoseEstimator).parameters.items()}   # one source of truth
PARAMS = [
    ParamSpec("pulleys", _D["pulleys"], "pulley model in the iterations: frozen at x_d (section 3.2) or full",
              choices=("frozen", "full")),
    ParamSpec("max_iterations", _D["max_iterations"], "Levenberg-Marquardt iterations per solve [-]", range=(1, 1000)),
    ParamSpec("xtol", _D["xtol"], "convergence: Gauss-Newton step below this [m, rad]", range=(1e-15, 1e-3)),
]


def parameters(robot) -> list[ParamSpec]:
    """Every parameter of the node besides CdprNode's (docs/parameters.md)."""
    return [*PARAMS, *calibration_params(robot.m)]


class ForwardKinematicsNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("forward_kinematics", **kwargs)
        self.estimator = PoseEstimator(self.robot)
        self.params = ParameterSet(self, parameters(self.robot),
                                   lambda v: startup_calibration(self.robot, v), self._apply)
        self.estimator.calibration = startup_calibration(self.robot, self.params.values)
        self.pose_pub = self.create_publisher(PoseStamped, "platform/pose", CONTROL)
        self.wrench_pub = self.create_publisher(WrenchStamped, "platform/wrench", CONTROL)
        self.diag_pub = self.create_publisher(ForwardKinematicsDiagnostics, "forward_kinematics/diagnostics", CONTROL)
        # the load compensation's identified cable settlement (none published: the FK takes θ as it is)
        self.create_subscription(JointState, "load_compensation/settlement", self._keep_settlement, CONTROL,
                                 adapted=True)
        self.sync = StampSync(self, {
            "theta": (JointState, "winch/state"),
            "f": (CableForces, "cable_forces"),
            "setpoint": (OperationalSetpoint, "setpoint"),
        }, primary="f", callback=self._cycle, mode=self.sync_mode)

    def _keep_settlement(self, msg: JointState) -> None:
        s = np.asarray(msg.position, dtype=float)
        self.estimator.settlement = s if s.shape == (self.robot.m,) and all_finite(s.tolist()) else None

    def _apply(self, v: dict) -> None:
        e = self.estimator
        e.pulleys = v["pulleys"]
        e.solver.max_iterations = int(v["max_iterations"])
        e.solver.xtol = float(v["xtol"])

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        position, forces = msgs["theta"].position, msgs["f"].f
        x_d = setpoint_pose(msgs["setpoint"])
        header = self.header(t_ns)
        m = self.robot.m
        if len(position) != m or len(forces) != m or not (all_finite(position) and all_finite(forces)
                                                          and all_finite(x_d)):
            self.diag_pub.publish(builder(ForwardKinematicsDiagnostics)(
                header=header, formulation="elastic", termination=ForwardKinematicsDiagnostics.INVALID_INPUT,
                converged=False))
            self.report(DiagnosticStatus.ERROR, "invalid input (shape or non-finite)", stamp_ns=t_ns)
            return
        theta, f = np.asarray(position, dtype=float), np.asarray(forces, dtype=float)
        start = time.perf_counter()
        x, w = self.estimator.update(theta, f, x_d)
        result = self.estimator.result
        solve_time = time.perf_counter() - start
        self.diag_pub.publish(builder(ForwardKinematicsDiagnostics)(  # every field given: one constructor call
            header=header, formulation="elastic", solve_time=solve_time, termination=TERMINATION[result.termination],
            converged=result.converged, iterations=result.iterations, residual_norm=float(result.residual_norm)))
        if result.converged:
            self.report(DiagnosticStatus.OK, "converged", stamp_ns=t_ns)
        else:
            self.report(DiagnosticStatus.WARN, f"not converged ({result.termination})", stamp_ns=t_ns)
        self.pose_pub.publish(builder(PoseStamped)(header=header, pose=pose_to_msg(x)))
        self.wrench_pub.publish(builder(WrenchStamped)(header=header, wrench=wrench_to_msg(w)))


def main(args=None):
    spin_node(ForwardKinematicsNode, args)


if __name__ == "__main__":
    main()
