"""The control architecture of Fig. 3.4 as one object: the stages the nodes run, in one process.

Per period: friction compensation (3.44) -> forward kinematics (3.7)-(3.9) and w = -A^T f ->
force set-point (3.26)-(3.28) -> hybrid position/force control (5.1), when configured -> cable force
control (3.19)-(3.23) and OSPC (3.16) -> safety -> joint command θ_d = IK{x_d + x_OSPC + x_HPFC} -
Δq_CFC (5.1), (5.10). Switching between force control and IK-only control, or the CFC or OSPC on or
off, is bumpless (:mod:`cdpr_control.control.bumpless`): the outputs are blended in and out over
``transfer_time`` and an unused controller's integrator is held at zero. The ROS nodes wrap exactly these stage
objects one per node; this class chains them directly, which is what the closed-loop tests, the
benchmarks and offline studies use when the ROS transport is not the subject.

Offset stages are the further offset inputs of the joint command (load compensation (4.6), ...):
objects with ``offset(inputs: LoopInputs) -> OffsetOutput``, computed after the forward kinematics and
summed by the same :class:`cdpr_control.control.offset_inputs.OffsetInputs` as in the joint command node
(enable, ramped switching over ``transfer_time``). A stage may also hand the force set-point a model
wrench (an identified payload), added to w_dyn of (3.26).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdpr_control import kernels
from cdpr_control.control.bumpless import Blend
from cdpr_control.control.cable_force_control import CableForceControl, CFCParams
from cdpr_control.model.calibration import DEFAULT_WINDOW
from cdpr_control.control.filters import LowPass
from cdpr_control.control.force_setpoint import ForceSetpoint, ForceSetpointParams
from cdpr_control.control.pose_estimator import PoseEstimator
from cdpr_control.control.friction_compensation import FrictionCompensation, FrictionCompensationParams
from cdpr_control.control.hybrid_force_control import (FORCE_CONTROLLED, CFCCoupling, HPFCParams,
    HybridForceControl, expected_contact_wrench, select_position_feedback, task_force_direction)
from cdpr_control.control.joint_command import JointCommand
from cdpr_control.control.offset_inputs import OffsetInputs, OffsetSample
from cdpr_control.control.ospc import OperationalSpacePositionController, OSPCParams
from cdpr_control.control.preconditions import check_force_control, planned_home_forces
from cdpr_control.control.safety import ForceWatch, SafetyConfig, SafetyMonitor, braking


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
    hpfc: object = None      # HPFCState of the hybrid position/force control, None without it
    offsets: dict = field(default_factory=dict)   # per offset stage, its output x (6,)


class ControlLoop:
    def __init__(self, robot, dt: float, params: ControlLoopParams | None = None, offset_stages: dict | None = None):
        p = params or ControlLoopParams()
        self.robot, self.dt, self.params = robot, dt, p
        self.friction = FrictionCompensation(robot, dt, p.friction)
        self.estimator = PoseEstimator(robot, calibration_window=p.calibration_window)
        self.force = ForceSetpoint(robot, dt, p.force)
        # the loop runs the CFC in every mode (its filter and calibration stay current) and blends
        # its output; the stage's own on/off is for the node, which has no blend
        self.cfc = CableForceControl(robot, dt, p.cfc, enabled=True, calibration_window=p.calibration_window)
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
        self.blend_hpfc = Blend(p.transfer_time, dt, force_control)
        self.refusal: str | None = None          # why a live switch-off of the OSPC is not honoured
        self._checked = (force_control, p.ospc_enabled, p.cfc_enabled)
        self.hpfc = None if p.hpfc is None else HybridForceControl(robot, dt, p.hpfc, enabled=p.hpfc_enabled)
        self.coupling = None if p.hpfc is None else CFCCoupling(p.hpfc.T_MA, dt)
        self.contact_filter = LowPass(p.force.T_wrench_filter, dt)   # as the distribution's wrench filter
        self.dq_cfc = np.zeros(robot.m)
        self.offset_stages = dict(offset_stages or {})
        self.offsets = OffsetInputs(self.offset_stages, dt, p.transfer_time)
        self.state: LoopState | None = None      # the last period (a set-point source may close the loop on it)

    def _hpfc_cfc(self, hpfc, f_d, f, ik_d, cfc_on: bool):
        """Section 5.1.2, the cable force control under hybrid force control -> (the CFC's set-point,
        its feed-forward, paused, x_comp (6,) the offset that hands the contact force over).

        The CFC is paused in A-C and runs from D on (:meth:`CFCCoupling.run`, the node
        ``cable_force_controller`` runs the same); it resumes
        bumpless (feedback filter restarted at the measured forces, the integral part taking the
        proportional part's step). Its feed-forward presses along the task axis with the expected
        contact force F_ff (the distribution's wrench carries it, :func:`expected_contact_wrench`);
        x_comp = -F_ff / k_t z_t lifts the position offset by what that press would push the
        robot, k_t the contact stiffness measured in B (``HybridForceControl.k_contact``), so the
        contact force passes from x_t to the cable forces without a step and x_t no longer presses
        the robot tens of millimetres into the surface (which slackens the cables it unloads).
        The integral part of the CFC along a = (A^T)_F^T z_t (the cable forces that change the
        contact force) is handed over to x_t with the CFC's T_i (``HybridForceControl.absorb``):
        the PID (5.3) owns the steady contact force, and nothing of it is left in Δq_CFC when the
        contact ends.
        """
        state = self.state.hpfc if self.state is not None else None
        F_c = self.contact_filter.update(state.F_d if state is not None and state.state in FORCE_CONTROLLED else 0.0)
        a = task_force_direction(ik_d.AT, hpfc.z_t)
        f_set, f_ff, paused, F_ff, F_a = self.coupling.run(hpfc.state, f_d, F_c, a, self.cfc.controller, f)
        k_t = self.hpfc.k_contact or self.hpfc.params.K_p
        x_comp = np.zeros(6)
        if F_ff != 0.0 and cfc_on:
            x_comp[:3] = -F_ff / k_t * hpfc.z_t
        if F_a != 0.0:
            self.hpfc.absorb(F_a / k_t)
        return f_set, f_ff, paused, x_comp

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
            self.hpfc.enabled = bool(value)
        elif (node, parameter) == ("cable_force_controller", "enabled"):
            self.params.cfc_enabled = bool(value)        # blended in or out (bumpless)
        else:
            raise ValueError(f"the in-process loop has no parameter {node}.{parameter}")

    def step(self, t: float, x_d, xdot_d, xddot_d, theta, thetadot, F_s, F_d0=None) -> LoopState:
        """One period from the set-point (pose, twist, acceleration, desired force F_d,0 of the force
        axes) and the winch measurements."""
        robot = self.robot
        if self.command.theta_d is None:
            self.command.reset(theta)
        ik_d = kernels.inverse_kinematics(robot, x_d)  # once per period, shared by three stages
        f = self.friction.update(F_s, theta, thetadot, ik_d.beta)
        x, w = self.estimator.update(theta, f, x_d, ik_d)
        inputs = LoopInputs(t, x_d, xdot_d, xddot_d, theta, f, x, w, ik_d)
        outputs = {name: stage.offset(inputs) for name, stage in self.offset_stages.items()}
        w_models = [out.w_model for out in outputs.values() if out.w_model is not None]
        # section 5.1.2: the expected contact reaction, not the measured one, in the distribution's
        # wrench; from the last period's state, so that the set-point the CFC holds from the
        # period A begins (the one before the approach) has no contact in it
        w_dist = w if self.state is None or self.state.hpfc is None else w + expected_contact_wrench(self.state.hpfc)
        dist = self.force.update(x_d, xdot_d, xddot_d, w_dist, ik_d.AT,
                                 w_model=sum(w_models) if w_models else None)
        p = self.params
        force_control = p.mode == "force_control"
        for blend in (self.blend_cfc, self.blend_ospc, self.blend_hpfc):
            blend.set_transfer_time(p.transfer_time)
        s_cfc = self.blend_cfc.update(force_control and p.cfc_enabled)
        if (force_control, p.ospc_enabled, p.cfc_enabled) != self._checked:   # a live change: check (3.1.3) once
            self._checked = (force_control, p.ospc_enabled, p.cfc_enabled)
            self.refusal = check_force_control(robot, robot.home, planned_home_forces(robot, p.force),
                                               p.ospc_enabled or not p.cfc_enabled) if force_control else None
        s_ospc = self.blend_ospc.update(force_control and (p.ospc_enabled or self.refusal is not None))
        s_hpfc = self.blend_hpfc.update(force_control)
        hpfc = None if self.hpfc is None else self.hpfc.update(np.zeros(3) if F_d0 is None else F_d0, w)
        if hpfc is None:
            f_d, f_ff, paused, x_comp = dist.f, None, False, None
        else:
            f_d, f_ff, paused, x_comp = self._hpfc_cfc(hpfc, dist.f, f, ik_d, s_cfc > 0.0)
        if not paused:                                 # section 5.1.2: held during contact establishment
            self.dq_cfc = self.cfc.update(f_d, f, theta, dist.f_min, dist.f_max, f_ff)
        dq_cfc = s_cfc * self.dq_cfc
        if s_cfc == 0.0:
            self.cfc.controller.pi.reset()           # track: no wind-up while the output is unused
        # Fig. 5.2: no position control along the force-controlled task z axis
        x_fb = x if hpfc is None or hpfc.state not in FORCE_CONTROLLED else select_position_feedback(x_d, x, hpfc.z_t)
        x_ospc = s_ospc * self.ospc.update(x_d, x_fb)
        if s_ospc == 0.0:
            self.ospc.reset()
        offsets = [x_ospc] if hpfc is None else [x_ospc, s_hpfc * hpfc.x + s_cfc * x_comp]
        faults = self.monitor.check(t, f=f, f_min=robot.cable.f_min, f_max=robot.cable.f_max, x_d=x_d, x=x,
                                    fk_converged=self.estimator.result.converged)
        self.offsets.ramp_time = p.transfer_time
        samples = {name: OffsetSample(t, out.active, out.x) for name, out in outputs.items()} if force_control else {}
        offset, offset_faults = self.offsets.update(t, samples)               # ik_only: ramped out
        offsets.append(offset)
        faults += offset_faults
        tripped = self.watch.update(f, robot.cable.f_min, robot.cable.f_max, x_d, sum(offsets), dq_cfc, dist.f,
                                    None if braking(faults) else x)     # (braking, the robot lags by design)
        if tripped is not None:
            faults.append(tripped)
        hold = any(fault.holds for fault in faults)
        theta_d = self.command.update(x_d, offsets, dq_cfc, hold=hold,       # s = 0: IK only (2.3.2)
                                      safe=None if tripped is None else self.watch.safe, f=f)
        self.state = LoopState(f, x, w, dist.f, int(dist.status), dq_cfc, x_ospc, theta_d, faults,
                               self.estimator.result.converged, hpfc,
                               {name: out.x for name, out in outputs.items()})
        return self.state
