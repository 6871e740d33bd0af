"""Node ``cable_force_controller``: joint-space cable force control (3.19)-(3.23).

Subscribes ``force_distribution`` (f_d, limits), ``cable_forces`` (f at the platform) and
``winch/state`` (θ, for the free length l_t (2.14)); publishes ``cable_force_controller/state``
(cdpr_msgs/ControllerState, ``output`` = Δq_CFC [m] per cable). Disabled, it publishes Δq_CFC = 0:
the IK-only reference control of section 2.3.2.

K_l of (3.23) is the thesis' linear model k_spec / l_t, or (default) the secant of the robot
file's non-linear cable (2.16)-(2.17): with the linear model the integrator must make up the
difference, which on the IPAnema 3's progressive 6 mm cable needs hundreds of newtons of
saturation range. The pre-tension elongation Δq_0 is taken at start-up from the first measured
forces (as the thesis does for the forward kinematics, section 3.2) in the same stiffness model,
so that f = f_d commands no change.
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import CableForces, ControllerState, ForceDistribution
from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import JointState

from cdpr_control import cable
from cdpr_control.cable_force_control import CableForceController, CFCParams

from .base import CdprNode, spin_node
from .parameters import ParameterSet, ParamSpec
from .qos import CONTROL
from .sync import StampSync

PARAMS = [
    ParamSpec("enabled", True, "cable force control on; off = IK-only reference control (2.3.2)"),
    ParamSpec("K_p", 0.85, "proportional gain K_p,CFC [-] (3.19), table 3.1", range=(0.0, 10.0)),
    ParamSpec("T_i", 0.1, "integrator reset time T_i,CFC [s] (3.19), table 3.1", range=(1e-3, 100.0)),
    ParamSpec("T_filter", 0.08, "PT1 time constant of the force feedback T_1,r [s] (3.20), table 3.1", range=(0.0, 1.0)),
    ParamSpec("F_sat_n", 200.0, "negative saturation of the PI part F_sat,n [N]", range=(0.0, 1e5)),
    ParamSpec("F_sat_p", 200.0, "positive saturation of the PI part F_sat,p [N]", range=(0.0, 1e5)),
    ParamSpec("widen_band", 50.0, "force distance to a limit where the saturation widens [N]", range=(1e-3, 1e5)),
    ParamSpec("widen_factor", 3.0, "saturation multiplier reached at a force limit [-]", range=(1.0, 100.0)),
    ParamSpec("stiffness_model", "nonlinear", "K_l of (3.23): linear (k_spec nominal / l_t, as the thesis) or "
              "nonlinear (secant of (2.16)-(2.17): the elongation of the robot file's cable model)",
              choices=("linear", "nonlinear")),
]


class CableForceControllerNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("cable_force_controller", **kwargs)
        m = self.robot.m
        self.names = [f"cable_{i + 1}" for i in range(m)]
        self.controller: CableForceController | None = None
        self.calibration: tuple[np.ndarray, np.ndarray] | None = None   # (f_0, l_t) at start-up
        self.enabled = True
        self.params = ParameterSet(self, PARAMS, self._validate, self._apply)
        self.publisher = self.create_publisher(ControllerState, "cable_force_controller/state", CONTROL)
        self.sync = StampSync(self, {
            "f_d": (ForceDistribution, "force_distribution"),
            "f": (CableForces, "cable_forces"),
            "theta": (JointState, "winch/state"),
        }, primary="f", callback=self._cycle, mode=self.sync_mode)

    @staticmethod
    def _cfc_params(v: dict) -> CFCParams:
        return CFCParams(K_p=v["K_p"], T_i=v["T_i"], T_filter=v["T_filter"], F_sat_n=v["F_sat_n"],
                         F_sat_p=v["F_sat_p"], widen_band=v["widen_band"], widen_factor=v["widen_factor"])

    def _validate(self, v: dict) -> None:
        self._cfc_params(v).validate()

    def _apply(self, v: dict) -> None:
        params = self._cfc_params(v)
        if self.controller is None:
            self.controller = CableForceController(self.robot.m, params, self.dt)
        else:
            self.controller.set_params(params)
        if v["enabled"] and not self.enabled:
            self.controller.pi.reset()           # bumpless: start the integrator from zero
        self.enabled = v["enabled"]
        if v["stiffness_model"] != getattr(self, "stiffness_model", None):
            self.stiffness_model = v["stiffness_model"]
            if self.calibration is not None:     # Δq_0 of the start-up forces in the new model
                self.controller.dq_0 = self._elongation(*self.calibration)

    def _stiffness(self, l_t):
        """K_l of (3.23): an array (linear, (2.15)) or the secant of (2.17) as a function of f_c,out."""
        if self.stiffness_model == "linear":
            return self.robot.cable.k_spec_nominal / l_t
        return lambda f_out: cable.stiffness(self.robot, np.maximum(f_out, 0.0), l_t)

    def _elongation(self, f, l_t) -> np.ndarray:
        """K_l^-1 f in the selected model: Δq_0 of the start-up forces, so f = f_d commands no change."""
        k_l = self._stiffness(l_t)
        return f / (k_l(f) if callable(k_l) else k_l)

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        fd_msg, f_msg, theta_msg = msgs["f_d"], msgs["f"], msgs["theta"]
        f_d = np.asarray(fd_msg.f_d)
        f = np.asarray(f_msg.f)
        theta = np.asarray(theta_msg.position)
        m = self.robot.m
        state = ControllerState(header=self.header(t_ns), controller="cable_force_controller",
                                enabled=self.enabled, names=self.names)
        valid = f_d.shape == f.shape == theta.shape == (m,) and np.all(np.isfinite(np.r_[f_d, f, theta]))
        if not valid:
            self.report(DiagnosticStatus.ERROR, "invalid input (shape or non-finite); output held at 0", stamp_ns=t_ns)
            state.output = [0.0] * m
            self.publisher.publish(state)
            return
        l_t = cable.total_free_length(self.robot, theta)                    # (2.14)
        k_l = self._stiffness(l_t)
        c = self.controller
        if self.enabled:
            if self.calibration is None:
                self.calibration = (f.copy(), l_t)
            if c.dq_0 is None:
                c.reset(self._elongation(*self.calibration), f=f)
            dq = c.update(f_d, f, k_l, np.asarray(fd_msg.f_min), np.asarray(fd_msg.f_max))
            state.reference, state.feedback = f_d.tolist(), c.f_filtered.tolist()
            state.error = (f_d - c.f_filtered).tolist()
            state.integrator = c.pi.integrator.tolist()
            state.feedforward = f_d.tolist()
            state.output = dq.tolist()
            state.saturated = c.pi.saturated.tolist()
            level = DiagnosticStatus.WARN if np.any(c.pi.saturated) else DiagnosticStatus.OK
            self.report(level, "saturated" if level else "ok", stamp_ns=t_ns)
        else:
            state.reference, state.feedback = f_d.tolist(), f.tolist()
            state.error = (f_d - f).tolist()
            state.output = [0.0] * m
        self.publisher.publish(state)


def main(args=None):
    spin_node(CableForceControllerNode, args)


if __name__ == "__main__":
    main()
