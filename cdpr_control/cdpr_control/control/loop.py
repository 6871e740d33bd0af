"""The control architecture of Fig. 3.4 as one object: the stages the nodes run, in one process.

Per period, in the order of the lockstep node graph: friction compensation (3.44) -> forward
kinematics (3.7)-(3.9) and w = -A^T f -> the offset stages -> hybrid position/force control (5.1),
when configured -> force set-point (3.26)-(3.28) with its expected contact force -> cable force
control (3.19)-(3.23) (under hybrid force control paused or coupled, section 5.1.2) and OSPC (3.16)
-> safety -> joint command θ_d = IK{x_d + x_OSPC + x_HPFC + ...} - Δq_CFC (5.1), (5.10).
Switching between force control and IK-only control, or the CFC or OSPC on or off, is bumpless
(:mod:`cdpr_control.control.bumpless`): the outputs are blended in and out over ``transfer_time``
and an unused controller's integrator is held at zero. The ROS nodes wrap exactly these stage
objects one per node and the offsets are summed by the joint command node's
:class:`cdpr_control.control.offset_inputs.OffsetInputs` in its order (``ospc``,
``hybrid_force_controller``, then the offset stages), so that with every blend at 1 the loop
computes the graph's numbers bit for bit (tests/graph/test_loop_equals_graph.py); this class
chains them directly, which is what the closed-loop tests, the benchmarks and offline studies use
when the ROS transport is not the subject.

Offset stages are the further offset inputs of the joint command (load compensation (4.6), ...):
objects with ``offset(inputs: LoopInputs) -> OffsetOutput``, computed after the forward kinematics and
summed with the OSPC's and the hybrid force controller's outputs (enable, ramped switching over
``transfer_time``). A stage may also hand the force set-point a model wrench (an identified
payload), added to w_dyn of (3.26).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from cdpr_control import kernels
from cdpr_control.control.bumpless import START_RAMP, Blend
from cdpr_control.control.cable_force_control import CableForceControl, CFCParams
from cdpr_control.model.calibration import DEFAULT_WINDOW
from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams
from cdpr_control.control.pose_estimator import PoseEstimator
from cdpr_control.control.friction_compensation import FrictionCompensation, FrictionCompensationParams
from cdpr_control.control.hybrid_force_control import (FORCE_CONTROLLED, ContactCableForceControl, HPFCParams,
    HybridForceStage, select_position_feedback)
from cdpr_control.control.joint_command import JointCommand
from cdpr_control.control.offset_inputs import OffsetInputs, OffsetSample
from cdpr_control.control.ospc import OperationalSpacePositionController, OSPCParams
from cdpr_control.control.preconditions import check_force_control, planned_home_forces
from cdpr_control.control.safety import ForceWatch, SafetyConfig, SafetyMonitor, braking


NO_FORCE = np.zeros(3)          # F_d,0 without a set-point's desired force (shared, read-only)
NO_FORCE.flags.writeable = False


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
    transfer_time: float = 0.5           # s, blend of the CFC and OSPC outputs on a switch (bumpless)
    start_ramp: float = START_RAMP       # s, the joint command's start ramp (JointCommand.reset)
    calibration_window: int = DEFAULT_WINDOW   # samples averaged for the start-up Δq_0 (3.9), (3.23)
    hpfc: HPFCParams | None = None       # hybrid position/force control stage (5.1); None: not in the loop
    hpfc_enabled: bool = False           # its `enabled` (M103/M104 switch it in a program)


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
    ik_d: object = None      # inverse_kinematics(robot, x_d); None: the stage takes what it needs of it,
                             # as its node does (kernels.inverse_kinematics_fields, one IK a period)


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
    hpfc: object = None      # HPFCState of the hybrid position/force control, None without it
    offsets: dict = field(default_factory=dict)   # per offset stage, its output x (6,)
    x_hpfc: np.ndarray | None = None   # x_d,HPFC + x_comp (the hybrid force controller's output), None without it


class ControlLoop:
    def __init__(self, robot, dt: float, params: ControlLoopParams | None = None, offset_stages: dict | None = None):
        p = params or ControlLoopParams()
        self.robot, self.dt, self.params = robot, dt, p
        self.friction = FrictionCompensation(robot, dt, p.friction)
        self.estimator = PoseEstimator(robot, calibration_window=p.calibration_window)
        self.force = ForceSetpoint(robot, dt, p.force)
        # the loop runs the CFC in every mode (its filter and calibration stay current) and blends
        # its output; the stage's own on/off is for the node, which has no blend
        self.cfc = CableForceControl(robot, dt, p.cfc, enabled=True, calibration_window=p.calibration_window,
                                     start_ramp=True)
        self.ospc = OperationalSpacePositionController(p.ospc, dt)
        self.monitor = SafetyMonitor(p.safety)
        self.watch = ForceWatch(p.safety, dt)     # the latched hold (tripped: the loop has failed)
        self.command = JointCommand(robot, dt)
        force_control = p.mode == "force_control"
        if force_control:
            # (3.1.3) concerns the cable force control without OSPC; neither on is position control
            reason = check_force_control(robot, robot.home, planned_home_forces(robot, p.force),
                                         p.ospc_enabled or not p.cfc_enabled)
            if reason:
                raise ValueError(reason)
        self.blend_cfc = Blend(p.transfer_time, dt, force_control and p.cfc_enabled)
        self.blend_ospc = Blend(p.transfer_time, dt, force_control and p.ospc_enabled)
        self.refusal: str | None = None          # why a live switch-off of the OSPC is not honoured
        self._checked = (force_control, p.ospc_enabled, p.cfc_enabled)
        # section 5.1.2: the stages the nodes hybrid_force_controller and cable_force_controller run
        # (its approach waits for the offset's switch-on ramp, transfer_time: HPFCParams.T_on)
        self.hpfc = None if p.hpfc is None else HybridForceStage(robot, dt, replace(p.hpfc, T_on=p.transfer_time),
                                                                 p.force.T_wrench_filter, enabled=p.hpfc_enabled)
        self.contact = None if p.hpfc is None else ContactCableForceControl(robot, self.cfc, p.hpfc.T_MA, dt)
        self._cfc_applied = False                # Δq_CFC applied in the last period (the node's hand-over)
        self._limits = None                      # the distribution's (f_min, f_max) of the last period (hybrid force control)
        self.dq_cfc = np.zeros(robot.m)
        self.offset_stages = dict(offset_stages or {})
        # the stage whose cable settlement the pose estimator takes (the load compensation; section 4.1.3)
        self._settlement_source = next((stage for stage in self.offset_stages.values()
                                        if hasattr(stage, "pose_settlement")), None)
        # the offset inputs in the joint command node's order (params: offset_inputs)
        names = ["ospc"] + ([] if self.hpfc is None else ["hybrid_force_controller"]) + list(self.offset_stages)
        self.offsets = OffsetInputs(names, dt, p.transfer_time)
        self.state: LoopState | None = None      # the last period (a set-point source may close the loop on it)

    def set_home_calibration(self, f_home) -> None:
        """Δq_0 from the forces f_home (m,) [N] recorded when the encoders were set at home (2.3.2),
        for a start away from home (else the first samples are averaged)."""
        self.estimator.calibration.set_home(self.robot, f_home)
        self.estimator.dq_0 = None
        self.cfc.calibration.set_home(self.robot, f_home)
        self.cfc.controller.dq_0 = None

    @property
    def failure(self) -> str | None:
        """Why the force watch holds the loop (a running program has failed), None while it does not."""
        return None if self.watch.fault is None else self.watch.fault.message

    def set_parameter(self, node: str, parameter: str, value) -> None:
        """A parameter command of a program (M103/M104, M101/M102) applied to the stage it names."""
        if (node, parameter) == ("hybrid_force_controller", "enabled") and self.hpfc is not None:
            self.hpfc.control.enabled = bool(value)
        elif (node, parameter) == ("cable_force_controller", "enabled"):
            self.params.cfc_enabled = bool(value)        # blended in or out (bumpless)
        else:
            raise ValueError(f"the in-process loop has no parameter {node}.{parameter}")

    def step(self, t: float, x_d, xdot_d, xddot_d, theta, thetadot, F_s, F_d0=None, w_user=None) -> LoopState:
        """One period from the set-point (pose, twist, acceleration, desired force F_d,0 of the force
        axes) and the winch measurements. ``w_user``: while a user guides (section 5.2), the user's
        wrench w_Adm (5.9) the admittance controller computed with this set-point (the force
        distribution node's ``guiding_controller`` input), else None: the force set-point's hand's
        reserve (:meth:`cdpr_control.control.force_setpoint.ForceSetpoint.set_user_wrench`)."""
        robot = self.robot
        if self.command.theta_d is None:
            self.command.reset(theta, self.params.start_ramp)
        # the IK of x_d that the stages share, taken once (a node's stage takes its fields itself, of
        # the same computation: kernels.inverse_kinematics_fields; none while x_d repeats: holding)
        ik_d = kernels.setpoint_ik(robot, x_d)
        f = self.friction.update(F_s, theta, thetadot, ik_d.beta)
        x, w = self.estimator.update(theta, f, x_d, ik_d)
        outputs = {}
        if self.offset_stages:
            inputs = LoopInputs(t, x_d, xdot_d, xddot_d, theta, f, x, w)
            outputs = {name: stage.offset(inputs) for name, stage in self.offset_stages.items()}
            if self._settlement_source is not None:  # the identified settlement, for the next period's pose
                self.estimator.settlement = self._settlement_source.pose_settlement()
        w_models = [out.w_model for out in outputs.values() if out.w_model is not None] if outputs else None
        hpfc = x_hpfc = contact = None
        if self.hpfc is not None:
            # section 5.1.2: x_t takes over what the CFC's integral part handed over in the last period
            self.hpfc.take_over(self.contact.F_a)
            # F_d limited to the pose's capacity with the distribution's limits of the last period
            hpfc, x_hpfc = self.hpfc.update(NO_FORCE if F_d0 is None else F_d0, w, self._cfc_applied, x_d,
                                            self._limits)
            contact = (hpfc.state, hpfc.F_d0, hpfc.F_vec)     # its expected contact force in the wrench
        self.force.set_user_wrench(w_user)
        dist = self.force.update(x_d, xdot_d, xddot_d, w, w_model=sum(w_models) if w_models else None,
                                 contact=contact, AT=ik_d.AT)
        self._limits = (dist.f_min, dist.f_max)
        p = self.params
        force_control = p.mode == "force_control"
        for blend in (self.blend_cfc, self.blend_ospc):
            blend.set_transfer_time(p.transfer_time)
        s_cfc = self.blend_cfc.update(force_control and p.cfc_enabled)
        if (force_control, p.ospc_enabled, p.cfc_enabled) != self._checked:   # a live change: check (3.1.3) once
            self._checked = (force_control, p.ospc_enabled, p.cfc_enabled)
            self.refusal = check_force_control(robot, robot.home, planned_home_forces(robot, p.force),
                                               p.ospc_enabled or not p.cfc_enabled) if force_control else None
        s_ospc = self.blend_ospc.update(force_control and (p.ospc_enabled or self.refusal is not None))
        if hpfc is None:
            self.dq_cfc = self.cfc.update(dist.f, f, theta, dist.f_min, dist.f_max, x_d=x_d)
        else:                                          # section 5.1.2: held during contact establishment
            self.dq_cfc = self.contact.update(hpfc.state, hpfc.F_d0, x_d, dist.f, f, theta, dist.f_min, dist.f_max,
                                              hpfc.F_vec)
        dq_cfc = s_cfc * self.dq_cfc
        self._cfc_applied = s_cfc > 0.0
        if s_cfc == 0.0:
            self.cfc.controller.pi.reset()           # track: no wind-up while the output is unused
        # Fig. 5.2: no position control along the force-controlled task z axis
        x_fb = x if hpfc is None or hpfc.state not in FORCE_CONTROLLED else select_position_feedback(x_d, x, hpfc.z_t)
        x_ospc = s_ospc * self.ospc.update(x_d, x_fb)
        if s_ospc == 0.0:
            self.ospc.reset()
        faults = self.monitor.check(t, f=f, f_min=robot.cable.f_min, f_max=robot.cable.f_max, x_d=x_d, x=x,
                                    fk_converged=self.estimator.result.converged)
        self.offsets.ramp_time = p.transfer_time
        # the joint command's offset inputs, as its node sums them (OffsetInputs): ramped in and out
        samples = {}
        if force_control:                                                   # ik_only: ramped out
            samples["ospc"] = OffsetSample(t, True, x_ospc)
            if hpfc is not None:
                samples["hybrid_force_controller"] = OffsetSample(t, hpfc.active, x_hpfc)
            if outputs:
                samples.update({name: OffsetSample(t, out.active, out.x) for name, out in outputs.items()})
        offset, offset_faults = self.offsets.update(t, samples)
        faults += offset_faults
        tripped = self.watch.update(f, robot.cable.f_min, robot.cable.f_max, x_d, offset, dq_cfc, dist.f,
                                    x if not faults or not braking(faults) else None)   # (braking, the robot lags by design)
        if tripped is not None:
            faults.append(tripped)
        hold = bool(faults) and any(fault.holds for fault in faults)     # (no fault: most periods)
        theta_d = self.command.update(x_d, [offset], dq_cfc, hold=hold,     # s = 0: IK only (2.3.2)
                                      safe=None if tripped is None else self.watch.safe, f=f)
        self.state = LoopState(f, x, w, dist.f, int(dist.status), dq_cfc, x_ospc, theta_d, faults,
                               self.estimator.result.converged, hpfc,
                               {name: out.x for name, out in outputs.items()}, x_hpfc)
        return self.state
