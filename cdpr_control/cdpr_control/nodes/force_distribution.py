"""Node ``force_distribution``: wrench set-point (3.26) and cable force set-point f_d (3.27)-(3.28).

Subscribes ``setpoint`` (x_d, ẋ_d, ẍ_d) and ``platform/wrench`` (the measured w = -A^T f of the
forward kinematics node); publishes ``force_distribution`` (cdpr_msgs/ForceDistribution: f_d,
f_ref, limits used, w_d, status and solver diagnostics). Service ``force_distribution/set_tension_level``
(cdpr_msgs/SetTensionLevel).

w_d = w + (I - G_w) w_dyn (3.26): the measured wrench plus the change of the model wrench
(2.33) of the desired motion over the delay T_d,w (Smith predictor, section 3.6.1), so that the
cable force control acts in the null space. ``wrench_source = model`` uses w_d = w_dyn alone (3.1).
The distribution is solved for A^T at x_d; the tension level 0..1 sets f_ref = f_min + level
(f_max - f_min) (3.27): 0 is the minimal tension (QP), 0.5 the medium one (= ACF).
"""
from __future__ import annotations

import numpy as np
from cdpr_msgs.msg import ForceDistribution, OperationalSetpoint
from cdpr_msgs.srv import SetTensionLevel
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import WrenchStamped
from rclpy.parameter import Parameter

from cdpr_control.dynamics import platform_wrench
from cdpr_control.filters import LowPass
from cdpr_control.force_distribution import BACKENDS, METHODS, BorderPolicy, ForceDistributor, Status
from cdpr_control.kinematics import inverse_kinematics
from cdpr_control.wrench_setpoint import WrenchSetpoint

from .base import CdprNode, spin_node
from .conversions import accel_from_msg, pose_from_msg, twist_from_msg, wrench_from_msg, wrench_to_msg
from .parameters import ParameterSet, ParamSpec
from .qos import CONTROL
from .sync import StampSync


class ForceDistributionNode(CdprNode):
    def __init__(self, **kwargs):
        super().__init__("force_distribution", **kwargs)
        c = self.robot.cable
        specs = [
            ParamSpec("method", "qp", "cable force algorithm: " + ", ".join(sorted(METHODS)), choices=tuple(sorted(METHODS))),
            ParamSpec("backend", "daqp", "QP solver: " + ", ".join(BACKENDS), choices=tuple(BACKENDS)),
            ParamSpec("tension_level", 0.0, "f_ref = f_min + level (f_max - f_min) (3.27) [0..1]", range=(0.0, 1.0)),
            ParamSpec("f_min", c.f_min.tolist(), "minimum cable force per cable [N] (2.39)"),
            ParamSpec("f_max", c.f_max.tolist(), "maximum cable force per cable [N] (2.39)"),
            ParamSpec("overload_factor", 1.0, "f_max may rise to this multiple at the workspace border (3.6.2) [-]", range=(1.0, 5.0)),
            ParamSpec("overload_rate", 0.0, "max rate of the overload raise [1/s]; 0 = instant", range=(0.0, 1e3)),
            ParamSpec("wrench_source", "measured", "measured: w_d = w + (I - G_w) w_dyn (3.26); model: w_d = w_dyn (3.1)",
                      choices=("measured", "model")),
            ParamSpec("T_d_w", 0.01, "transfer delay T_d,w of the Smith predictor (3.25) [s]", range=(0.0, 0.5)),
            ParamSpec("wrench_deviation_max", 0.1, "saturation of the measured disturbance wrench (3.24) "
                      "relative to the platform weight m g (torques: times the mean platform radius) [-]; "
                      "limits how far oscillations and model errors reach f_d (section 3.6.1)", range=(0.0, 100.0)),
            ParamSpec("T_wrench_filter", 0.08, "PT1 time constant on the measured wrench [s]: keeps the loop "
                      "f -> w -> f_d -> f of (3.26) from feeding sensor dynamics back at full gain", range=(0.0, 1.0)),
        ]
        self.distributor: ForceDistributor | None = None
        self.f_ref_override: np.ndarray | None = None
        self.smith = WrenchSetpoint(0.01, self.dt)
        self.wrench_filter = LowPass(0.08, self.dt)
        self.params = ParameterSet(self, specs, self._validate, self._apply)
        self.publisher = self.create_publisher(ForceDistribution, "force_distribution", CONTROL)
        self.create_service(SetTensionLevel, "force_distribution/set_tension_level", self._on_set_tension_level)
        self.sync = StampSync(self, {
            "setpoint": (OperationalSetpoint, "setpoint"),
            "wrench": (WrenchStamped, "platform/wrench"),
        }, primary="wrench", callback=self._cycle, mode=self.sync_mode)

    def _validate(self, v: dict) -> None:
        m = self.robot.m
        f_min, f_max = np.asarray(v["f_min"], dtype=float), np.asarray(v["f_max"], dtype=float)
        if f_min.shape != (m,) or f_max.shape != (m,):
            raise ValueError(f"f_min and f_max need {m} values each")
        if not (np.all(np.isfinite(f_min)) and np.all(np.isfinite(f_max)) and np.all(f_min >= 0) and np.all(f_min < f_max)):
            raise ValueError("force limits need 0 <= f_min < f_max for every cable")
        BorderPolicy(overload_factor=v["overload_factor"]).validate()

    def _apply(self, v: dict) -> None:
        f_min, f_max = np.asarray(v["f_min"], dtype=float), np.asarray(v["f_max"], dtype=float)
        border = BorderPolicy(overload_factor=v["overload_factor"], rate=v["overload_rate"] or None)
        d = self.distributor
        if d is None or (d.method, d.backend, d.border) != (v["method"], v["backend"], border) \
                or not (np.array_equal(d.f_min, f_min) and np.array_equal(d.f_max, f_max)):
            self.distributor = ForceDistributor(self.robot.m, f_min, f_max, method=v["method"],
                                                backend=v["backend"], border=border)
        self.f_ref_override = None                     # a parameter change wins over the service
        self.distributor.set_reference(f_min + v["tension_level"] * (f_max - f_min))
        if v["T_d_w"] != self.smith.T_d_w:
            self.smith.set_delay(v["T_d_w"])
        self.wrench_source = v["wrench_source"]
        self.wrench_filter.set_time_constant(v["T_wrench_filter"])
        p = self.robot.platform
        weight = p.mass * float(np.linalg.norm(self.robot.gravity))
        radius = float(np.mean(np.linalg.norm(self.robot.b, axis=1)))
        self.w_dist_max = v["wrench_deviation_max"] * weight * np.r_[np.ones(3), np.full(3, radius)]

    def _on_set_tension_level(self, request, response):
        d = self.distributor
        if len(request.f_ref):
            f_ref = np.asarray(request.f_ref, dtype=float)
            if f_ref.shape != (self.robot.m,) or np.any(f_ref < d.f_min) or np.any(f_ref > d.f_max) or not np.all(np.isfinite(f_ref)):
                response.success, response.message = False, f"f_ref needs {self.robot.m} values within [f_min, f_max]"
            else:
                d.set_reference(f_ref)
                self.f_ref_override = f_ref
                response.success, response.message = True, "f_ref set"
        else:
            result = self.set_parameters([Parameter("tension_level", value=float(request.level))])[0]
            response.success, response.message = result.successful, result.reason or "tension level set"
        response.f_ref = d.f_ref.tolist()
        return response

    def _cycle(self, msgs: dict, t_ns: int) -> None:
        sp = msgs["setpoint"]
        x_d, xdot_d, xddot_d = pose_from_msg(sp.pose), twist_from_msg(sp.velocity), accel_from_msg(sp.acceleration)
        w = wrench_from_msg(msgs["wrench"].wrench)
        w_dyn = platform_wrench(self.robot, x_d, xdot_d, xddot_d)          # (2.33), A^T f = -w convention
        if self.wrench_source == "measured" and np.all(np.isfinite(w)):
            w_d = self.smith.update(self.wrench_filter.update(w), w_dyn, self.w_dist_max)  # (3.26)
        else:
            w_d = w_dyn                                                     # (3.1)
        AT = inverse_kinematics(self.robot, x_d).AT
        res = self.distributor.solve(AT, w_d, self.dt)                       # (3.27)-(3.28)
        out = ForceDistribution(header=self.header(t_ns), f_d=res.f.tolist(), f_ref=res.f_ref.tolist(),
                                f_min=res.f_min.tolist(), f_max=res.f_max.tolist(), w_d=wrench_to_msg(w_d),
                                method=res.method, status=int(res.status), max_violation=float(res.max_violation),
                                residual=float(res.residual), iterations=int(res.iterations),
                                solve_time=float(res.solve_time))
        self.publisher.publish(out)
        if res.status == Status.INFEASIBLE:
            self.report(DiagnosticStatus.ERROR, f"no feasible distribution: max violation {res.max_violation:.1f} N",
                        stamp_ns=t_ns)
        elif res.status == Status.OVERLOADED:
            self.report(DiagnosticStatus.WARN, "feasible only with raised f_max (workspace border)", stamp_ns=t_ns)
        else:
            self.report(DiagnosticStatus.OK, "feasible", stamp_ns=t_ns)


def main(args=None):
    spin_node(ForceDistributionNode, args)


if __name__ == "__main__":
    main()
