"""The pose estimator of the control loop (Fig. 3.4, section 3.2): elastic forward kinematics
(3.7)-(3.9) of each period and the measured wrench w = -A^T(x) f (2.11).

The solvers are in :mod:`cdpr_control.model.forward_kinematics`; this stage adds what the loop needs:
the warm start at x_d with frozen pulleys, the encoder calibration's Δq_0 and the last converged pose.
"""
from __future__ import annotations

import numpy as np

from cdpr_control import kernels
from cdpr_control.model import cable
from cdpr_control.model.calibration import DEFAULT_WINDOW, StartupCalibration
from cdpr_control.model.forward_kinematics import FKResult, ForwardKinematics


class PoseEstimator:
    """The forward kinematics stage of the control loop (Fig. 3.4, section 3.2).

    Per period: the elastic FK (3.7)-(3.9) from θ and f, warm-started at x_d with the pulleys
    frozen there, and the measured wrench w = -A^T(x) f (2.11). The start-up elongation Δq_0 is
    the encoder calibration's (:mod:`cdpr_control.model.calibration`): the home calibration when given
    (``calibration.set_home``), else the mean of the first ``calibration_window`` samples. A solve
    that does not converge keeps the last converged pose (x_d before the first) and says so in
    ``result``.

    ``xtol`` 1e-8 (10 nm, 10 nrad; the encoders resolve micrometres): with the elastic residual of
    measured forces the Gauss-Newton step can stay above 1e-9 from rounding alone (seen on the Mini
    under the mismatched plant: 30 iterations between 1e-9 and 3e-9 without moving the pose, which a
    1e-8 tolerance reaches in 3), and a solve that does not converge holds the loop. With the
    large residuals of forces and lengths no pose explains (8.8 N on the Mini's demo, 1.8 kN on the
    IPAnema 3 under a payload) the last step, just above 1e-8, gains less than the cost's rounding:
    the solver takes such steps (docs/model.md, "Steps within the cost's rounding") instead of
    stalling into ``max_iterations``.

    ``settlement`` (m,) [m] or None: the growth of the unstretched cable lengths under load since
    the cables settled (section 4.1.3), which the encoders do not see: a settled cable is longer by
    s_i at the same winch length and force, so the FK takes θ + s as the winch lengths. The load
    compensation's identified settlement model sets it (``LoadCompensation.pose_settlement``; None,
    the default, where the ratio was not identified): without it the OSPC holds the forward
    kinematics' pose while the settled platform hangs lower (docs/load_compensation.md, cause A).
    """

    def __init__(self, robot, pulleys: str = "frozen", max_iterations: int = 30, xtol: float = 1e-8,
                 calibration_window: int = DEFAULT_WINDOW):
        self.robot = robot
        self.solver = ForwardKinematics(robot, xtol=xtol, max_iterations=max_iterations)
        self.pulleys = pulleys
        self.calibration = StartupCalibration(calibration_window)
        self.dq_0: np.ndarray | None = None
        self.x: np.ndarray | None = None
        self.result: FKResult | None = None
        self.settlement: np.ndarray | None = None
        kernels.warm_up(robot)               # the compiled FK loaded now, not in the first period

    def update(self, theta, f, x_d, ik_d=None) -> tuple[np.ndarray, np.ndarray]:
        """-> (x, w): the pose estimate and the wrench of the measured forces about its origin.

        ik_d: the IK of x_d when the caller has it (:func:`cdpr_control.kernels.setpoint_ik`, as
        ControlLoop hands it over), else taken here of the same computation.
        """
        if self.calibration.update(f, theta) or self.dq_0 is None:            # (3.7) at calibration
            c = self.calibration
            self.dq_0 = cable.elongation_from_force_and_winch_length(self.robot, c.f_0, c.theta_0)
        if self.settlement is not None:                                     # section 4.1.3
            theta = np.asarray(theta, dtype=float) + self.settlement
        self.result = self.solver.elastic(theta, f, x_d, self.dq_0, pulleys=self.pulleys, ik_d=ik_d)
        if self.result.converged:
            self.x = self.result.x
        x = self.x if self.x is not None else np.asarray(x_d, dtype=float)
        return x, kernels.measured_wrench(self.robot, x, f)                  # (2.11)
