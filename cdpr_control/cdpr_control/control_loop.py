"""The control architecture of Fig. 3.4 as one object: the stages the nodes run, in one process.

Per period: friction compensation (3.44) -> forward kinematics (3.7)-(3.9) and w = -A^T f ->
offset stages -> force set-point (3.26)-(3.28) -> cable force control (3.19)-(3.23) and OSPC (3.16)
-> safety -> joint command θ_d = IK{x_d + x_OSPC + Σ offsets} - Δq_CFC (5.10). The ROS nodes wrap
exactly these stage objects one per node; this class chains them directly, which is what the
closed-loop tests, the benchmarks and offline studies use when the ROS transport is not the subject.

Offset stages are the further offset inputs of the joint command (load compensation (4.6), hybrid
force control, admittance control, ...): objects with ``offset(inputs: LoopInputs) -> OffsetOutput``,
summed by the same :class:`cdpr_control.offset_inputs.OffsetInputs` as in the joint command node
(enable, ramped switching). A stage may also hand the force set-point a model wrench (an identified
payload), added to w_dyn of (3.26).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .cable_force_control import CableForceControl, CFCParams
from .force_setpoint import ForceSetpoint, ForceSetpointParams
from .forward_kinematics import PoseEstimator
from .friction_compensation import FrictionCompensation, FrictionCompensationParams
from .joint_command import JointCommand
from .kinematics import inverse_kinematics
from .offset_inputs import OffsetInputs, OffsetSample
from .ospc import OperationalSpacePositionController, OSPCParams
from .safety import SafetyConfig, SafetyMonitor


@dataclass
class ControlLoopParams:
    mode: str = "force_control"          # or "ik_only" (section 2.3.2)
    cfc_enabled: bool = True
    ospc_enabled: bool = True
    cfc: CFCParams = field(default_factory=CFCParams)
    ospc: OSPCParams = field(default_factory=OSPCParams)
    force: ForceSetpointParams = field(default_factory=ForceSetpointParams)
    friction: FrictionCompensationParams = field(default_factory=FrictionCompensationParams)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    offset_ramp_time: float = 0.2        # s, as the joint command's offset_ramp_time


@dataclass
class LoopInputs:
    """What an offset stage sees in a period (the content of the topics it would subscribe)."""

    t: float
    x_d: np.ndarray          # set-point pose, twist, acceleration
    xdot_d: np.ndarray
    xddot_d: np.ndarray
    theta: np.ndarray        # encoder cable lengths
    f: np.ndarray            # cable forces at the platform (friction-compensated)
    x: np.ndarray            # pose estimate (forward kinematics)
    w: np.ndarray            # measured wrench
    ik_d: object             # inverse_kinematics(robot, x_d)


@dataclass
class OffsetOutput:
    """An offset stage's output for a period (its ControllerState.enabled and .output)."""

    active: bool
    x: np.ndarray                        # offset [m, m, m, rad, rad, rad]
    w_model: np.ndarray | None = None    # wrench added to the force set-point's model wrench w_dyn


@dataclass
class LoopState:
    """What one period computed (the content of the nodes' topics)."""

    f: np.ndarray            # cable forces at the platform (friction-compensated)
    x: np.ndarray            # pose estimate
    w: np.ndarray            # measured wrench
    f_d: np.ndarray          # force set-point
    status: int              # force distribution status
    dq_cfc: np.ndarray       # CFC output
    x_ospc: np.ndarray       # OSPC output
    theta_d: np.ndarray      # drive command
    faults: list             # safety faults
    fk_converged: bool
    offsets: dict = field(default_factory=dict)   # per offset stage, its output x (6,)


class ControlLoop:
    def __init__(self, robot, dt: float, params: ControlLoopParams | None = None, offset_stages: dict | None = None):
        p = params or ControlLoopParams()
        self.robot, self.dt, self.params = robot, dt, p
        self.friction = FrictionCompensation(robot, dt, p.friction)
        self.estimator = PoseEstimator(robot)
        self.force = ForceSetpoint(robot, dt, p.force)
        self.cfc = CableForceControl(robot, dt, p.cfc, enabled=p.cfc_enabled)
        self.ospc = OperationalSpacePositionController(p.ospc, dt)
        self.monitor = SafetyMonitor(p.safety)
        self.command = JointCommand(robot, dt)
        self.offset_stages = dict(offset_stages or {})
        self.offsets = OffsetInputs(self.offset_stages, dt, p.offset_ramp_time)

    def step(self, t: float, x_d, xdot_d, xddot_d, theta, thetadot, F_s) -> LoopState:
        """One period from the set-point (pose, twist, acceleration) and the winch measurements."""
        robot = self.robot
        if self.command.theta_d is None:
            self.command.reset(theta)
        ik_d = inverse_kinematics(robot, x_d)          # once per period, shared by three stages
        f = self.friction.update(F_s, theta, thetadot, ik_d.beta)
        x, w = self.estimator.update(theta, f, x_d, ik_d)
        inputs = LoopInputs(t, x_d, xdot_d, xddot_d, theta, f, x, w, ik_d)
        outputs = {name: stage.offset(inputs) for name, stage in self.offset_stages.items()}
        w_models = [out.w_model for out in outputs.values() if out.w_model is not None]
        dist = self.force.update(x_d, xdot_d, xddot_d, w, ik_d.AT, w_model=sum(w_models) if w_models else None)
        dq_cfc = self.cfc.update(dist.f, f, theta, dist.f_min, dist.f_max)
        x_ospc = self.ospc.update(x_d, x) if self.params.ospc_enabled else np.zeros(6)
        faults = self.monitor.check(t, f=f, f_min=robot.cable.f_min, f_max=robot.cable.f_max, x_d=x_d, x=x,
                                    fk_converged=self.estimator.result.converged)
        force_control = self.params.mode == "force_control"
        samples = {name: OffsetSample(t, out.active, out.x) for name, out in outputs.items()} if force_control else {}
        offset, offset_faults = self.offsets.update(t, samples)               # ik_only: ramped out
        faults += offset_faults
        hold = any(fault.holds for fault in faults)
        if force_control:
            theta_d = self.command.update(x_d, [x_ospc, offset], dq_cfc, hold=hold)
        else:
            theta_d = self.command.update(x_d, [offset], hold=hold)
        return LoopState(f, x, w, dist.f, int(dist.status), dq_cfc, x_ospc, theta_d, faults,
                         self.estimator.result.converged, {name: out.x for name, out in outputs.items()})
