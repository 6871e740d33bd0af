"""The sweep's case runners, one per family, each in process: the robot's shipped parameter file in
:class:`cdpr_control.control.loop.ControlLoop` against the simulator (:func:`cdpr_sim.closed_loop.run`).

* contact (a): hybrid position/force control (section 5.1) pressing on a floor below the tool;
* guiding (b): hand guiding (section 5.2) at rest, pushed, and released for the eigenfrequency (5.12),
  with the friction identified on the plant first (``cdpr validate --friction``, :mod:`.friction`);
* payload (c): a payload step (section 4.1.3) under force control and under IK-only with load compensation;
* program (d): a G-code program through the workspace's border region under force control and IK-only.

Every run watches its cable forces: beyond DIVERGENCE_FACTOR * f_max, or non-finite, it is stopped
and the case fails as diverged; a run the loop's safety layer held (a holding fault: the force
watch, a pose lag ...) fails as held, with the fault. :func:`run_case` returns a case's :class:`CaseResult` (one per
controller for payloads); it never raises for what the controller did (an exception of the runner
itself is reported as the case's error).

Hand guiding runs the library's runner (:func:`cdpr_sim.hand_guiding.guiding_run`, the shipped
configuration). The other runners are the sweep's own: the library has no in-process runner for
contact at an arbitrary pose, and the payload one (:mod:`cdpr_tools.identify.load_steps`) takes
no orientation and has no divergence stop.
"""
from __future__ import annotations

import traceback
from dataclasses import dataclass, field, replace

import numpy as np

from cdpr_control.control.params import control_loop_params, load_params_file
from cdpr_control.control.hybrid_force_control import HPFCParams, HybridForceControl
from cdpr_control.model.kinematics import rotation_matrix
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import hold, run
from cdpr_sim.contacts import ContactMaterial, Plane, default_tool
from cdpr_sim.simulator import SimConfig, plant_of

from cdpr_tools.validate import criteria
from cdpr_tools.validate.criteria import DIVERGENCE_FACTOR

DT = 1e-3
NOMINAL_CONTACT_FORCE = {"ipanema3": 500.0,        # N, thesis section 5.1.3 (table 5.2)
                         "ipanema3_mini": 10.0}    # N, docs/hybrid_force_control.md (the Mini's shipped tuning)
CONTACT_FRACTIONS = (0.3, 0.6, 1.0)
FLOOR_STIFFNESS = (1e5, 5e5, 2e6)                  # N/m
FLOOR_DAMPING = 0.01                               # s: damping = this * stiffness (as the contact tests)
APPROACH_TIME = 0.1                                # s at v_max,HPFC from the pose to the floor
MIN_GAP = 1e-3                                     # m: above the plant's static sag at the start
CONTACT_TIME = 4.6                                 # s after the approach: 4 s settling + the steady window
# s at the pose under the shipped control before M103 (and before the floor is put in place): the
# start-up at a border pose swings the platform by +-4 mm and the cable forces by kN on the
# mismatched plant, which read as contact (A -> B -> D on no floor) and hit a floor 5 mm below
SETTLE_TIME = 1.0
FLOOR_AWAY = 0.2                                   # m below the gap while the robot settles
STEADY_WINDOW = 0.5                                # s: steady error over the last of the run
SETTLED_HOLD = 1.0                                 # s within the 2 % band after the impact: settled, the run ends
PAYLOAD_FRACTIONS = (0.25, 0.5, 1.0)               # of the pose's dynamic capacity (dynamic_capacity)
# -: peak over static response of an undamped mode to a load rising monotonically at any speed
# (Duhamel: x(t) = (1/k) ∫ F'(τ) (1 - cos ω(t - τ)) dτ <= 2 F / k for F' >= 0); a load put down
# needs the static capacity for this multiple of itself (dynamic_capacity)
DYNAMIC_LOAD_FACTOR = 2.0
# s: tared empty, the step (cosine), after it; the dwell lets the load compensation's output filter
# (T_output 1 s) and the OSPC's integral part (T_i / K_p about 2.6 s) reach the static sag
PAYLOAD_REST, PAYLOAD_RAMP, PAYLOAD_DWELL = 0.7, 0.3, 4.0
PAYLOAD_CONTROLLERS = ("force_control", "ik_lc")   # identify.load_steps.CONFIGS: the shipped graph; IK-only + (4.6)
REFERENCE = "ik"                                    # the uncompensated sag: IK-only, no load compensation
SAG_WINDOW = 0.3                                   # s: mean z error at the end of rest and dwell
PUSH_DIRECTIONS = ((1, 0, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1), (1, 1, -1), (-1, 1, 0))
PUSH_SHARE = 0.65                                  # of w_max (the Mini: 13 N, the push of issue 25): the nominal push
# -: the sweep's push is what a user can legitimately apply at the pose (push_scale): the nominal push
# scaled so that the hand's share of the cable forces stays within the reserve the pose leaves; a pose
# whose push would be below PUSH_MIN_SCALE of the nominal one is *beyond capacity*: the nominal push
# is applied and the criterion is that safety holds (criteria.BEYOND_CAPACITY_BANDS)
PUSH_MIN_SCALE = 0.2
# hand guiding is switched on once the platform has settled after the start-up, as a user switches
# it on a robot standing still (the tare, the thesis' w_init, taken while the platform still swings
# reads the swing's forces as a user wrench afterwards: docs/admittance.md): not before GUIDING_ENABLE
# [s] (the start-up has raised the cables to the planned forces), then in the first period in which
# the platform's true position has stayed within SETTLED_BAND [m, rad] of its mean over the last
# SETTLED_WINDOW [s] (translation: the distance; rotation: each angle), at the latest GUIDING_ENABLE_MAX
# (then the note says it had not settled). Measured at rest: the IPAnema 3's #21 (seed 2) swings
# 0.17 mm at 1 s and settles to a spread of 0.015 mm (noise) within 2 s (session 11)
GUIDING_ENABLE = 1.0
SETTLED_BAND = (5e-5, 5e-5)
SETTLED_WINDOW = 0.2
GUIDING_ENABLE_MAX = 3.0
# s after switching on: at rest; then the push rises (a hand, not a step), is held, released
REST_TIME, PUSH_RISE, PUSH_HOLD, PUSH_AFTER = 0.5, 0.1, 1.0, 0.8
# the eigenfrequency (5.12) on x, per robot (c [N/m], d [N s/m], m [kg]; push [N] for EIGEN_PUSH s):
# the Mini: table 5.3, row 3 (1.0 Hz); the IPAnema 3: the same 1.0 Hz and damping ratio 0.04 with
# the virtual mass of its shipped set (300 kg: a virtual mass below the 25 kg platform's excites
# the loop, `cdpr analyze stability`), pushed to a few mm
EIGEN = {"ipanema3_mini": {"cdm": (395.4, 5.0, 10.0), "push": 2.0},
         "ipanema3": {"cdm": (11843.5, 150.0, 300.0), "push": 65.0}}
EIGEN_ZONE = {"zones.rest.radius": 0.03, "zones.free.box": [0.05] * 6}   # the oscillation stays in the rest sphere
# s: push length, fitted window after the release: two periods of the 1 Hz oscillation. Over one
# (1 s, until session 11) the fit followed the platform's position error where the WFW shrinks the
# zone and with it the push and the oscillation: the Mini's #29 (border, seed 2; rest sphere 0.94 mm)
# swings 0.21 mm peak to peak with 0.13 mm rms between the true x and x_d, and read -2.73 % over 1 s,
# +0.38 % over 2 s, +0.55 % over 3 s (x_d itself: 0.000 %; home: -0.09, -0.000, +0.001 %)
EIGEN_PUSH, EIGEN_WINDOW = 0.2, 2.0


class Diverged(Exception):
    """A cable force beyond DIVERGENCE_FACTOR * f_max (or not finite): the run was stopped."""


class Done(Exception):
    """A run has shown what it was for (a contact force settled): it ends early."""


@dataclass
class CaseSpec:
    """One case: a family's run at a pose on a plant (``variant``: the family's parameters)."""

    family: str
    robot: str
    pose_index: int
    x: list                      # (6,) pose [m, rad]
    border: bool
    plant: str                   # mismatched or nominal
    seed: int                    # the mismatched plant's seed (0 for nominal)
    variant: dict = field(default_factory=dict)
    # the pulley friction of the case's friction compensation (validate.friction): {"source":
    # "shipped"} the robot file's; {"source": "identified", "file", "mu", "sigma", "F_pv", ...}
    friction: dict = field(default_factory=lambda: {"source": "shipped"})
    # the cable settlement of the payload cases' load compensation (validate.settlement): {"source":
    # "shipped"} the parameter file's; {"source": "identified", "file", "settlement_ratio", ...}
    settlement: dict = field(default_factory=lambda: {"source": "shipped"})


@dataclass
class CaseResult:
    spec: CaseSpec
    metrics: dict                # name -> value (NaN: not computed)
    checks: dict                 # metric name -> within its band
    status: str                  # passed, failed, diverged, held (the safety layer held the loop), refused (the
                                 # configuration is refused there), error
    note: str = ""
    wall_s: float = 0.0          # wall-clock time of the case's runs
    cpu_s: float = 0.0           # CPU time of its process over them (what the sweep costs on an idle machine)

    @property
    def passed(self) -> bool:
        return self.status == "passed"


class Recorder:
    """A ``before_step`` hook of :func:`cdpr_sim.closed_loop.run` recording the ground truth and
    the loop's state of each period, stopping the run when it diverges, and remembering the first
    holding fault of the loop (``held``: its time and message)."""

    def __init__(self, robot, hooks=()):
        self.f_stop = DIVERGENCE_FACTOR * np.asarray(robot.cable.f_max, dtype=float)
        self.hooks = list(hooks)
        self.rows = {"t": [], "x": [], "f": [], "w_contact": [], "state": []}
        self.diverged_at: float | None = None
        self.held: str | None = None

    def __call__(self, k, loop, sim):
        if k > 0:                                # the output of period k - 1 and what the loop computed then
            out = sim.output
            if not (np.all(np.isfinite(out.f)) and np.all(out.f <= self.f_stop)):
                self.diverged_at = float(out.t)
                raise Diverged(f"cable force {np.nanmax(out.f):.4g} N beyond {DIVERGENCE_FACTOR} f_max at "
                               f"t = {out.t:.3f} s")
            for key, value in (("t", out.t), ("x", out.x), ("f", out.f), ("w_contact", out.w_contact)):
                self.rows[key].append(np.copy(value))
            self.rows["state"].append(loop.state)
            if self.held is None and loop.state is not None:
                holding = [f for f in loop.state.faults if f.holds]
                if holding:
                    self.held = f"held at {out.t:.3f} s: {holding[0].code}: {holding[0].message}"
        for hook in self.hooks:
            hook(k, loop, sim)

    def array(self, key) -> np.ndarray:
        return np.array(self.rows[key])


def recorded_run(robot, recorder: Recorder, *args, **kwargs) -> bool:
    """:func:`cdpr_sim.closed_loop.run` with the recorder as its hook -> False when it diverged."""
    try:
        run(robot, *args, before_step=recorder, **kwargs)
    except Diverged:
        return False
    except Done:
        pass
    return True


def sim_config(spec: CaseSpec, **kwargs) -> SimConfig:
    return SimConfig(plant=spec.plant, plant_seed=spec.seed or 1, **kwargs)


def file_section(robot_name: str, node: str) -> dict:
    """A node's parameters in the robot's shipped parameter file."""
    return load_params_file(robot_name).get(node, {})


def shipped_hpfc(robot_name: str) -> HPFCParams:
    values = file_section(robot_name, "hybrid_force_controller")
    return HPFCParams(**{k: float(v) for k, v in values.items() if k in HPFCParams.__dataclass_fields__})


def judge(spec: CaseSpec, metrics: dict, diverged: bool, note: str = "", held: str | None = None,
          unjudged=()) -> CaseResult:
    """The case's result: its metrics against their bands; diverged, or held (``held``: the first
    holding fault, :attr:`Recorder.held`), fails whatever the metrics. ``unjudged``: metrics this
    case reports without judging them (the note says why)."""
    metrics = {**metrics, "diverged": float(diverged)}
    checks = {}
    for name, value in metrics.items():
        band = criteria.band_for(name, spec.plant, spec.variant.get("controller"))
        if band is not None and name not in unjudged:
            checks[name] = band.holds(value)
    status = "diverged" if diverged else "held" if held else "passed" if all(checks.values()) else "failed"
    return CaseResult(spec, metrics, checks, status, "; ".join(n for n in (note, held) if n))


# ---- (a) contact --------------------------------------------------------------------------------

def contact_case(spec: CaseSpec) -> CaseResult:
    """Press F_d = fraction * the nominal contact force on a floor of the given stiffness, placed
    APPROACH_TIME at v_max,HPFC (at least MIN_GAP) below the tool's lowest point at the pose once
    the robot has held the pose for SETTLE_TIME; hybrid force control enabled then (M103; A -> B ->
    D, Fig. 5.4). The run ends CONTACT_TIME after the approach (which starts after the joint
    command's switch-on ramp, HPFCParams.T_on), or earlier once the force has settled
    (:func:`_settled_watch`). A run the force watch holds says so (its reason)."""
    robot = load_robot(spec.robot)
    x = np.asarray(spec.x, dtype=float)
    hpfc = shipped_hpfc(spec.robot)
    F_d = spec.variant["fraction"] * NOMINAL_CONTACT_FORCE[spec.robot]
    k = spec.variant["stiffness"]
    radius, centre = default_tool(np.asarray(robot.b))
    lowest = (x[:3] + rotation_matrix(x[3:]) @ np.asarray(centre))[2] - radius
    gap = max(APPROACH_TIME * hpfc.v_max, MIN_GAP)
    floor = Plane.floor(lowest - gap - FLOOR_AWAY, ContactMaterial(stiffness=k, damping=FLOOR_DAMPING * k))
    force = np.array([0.0, 0.0, -F_d])
    source = lambda t: (x, np.zeros(6), np.zeros(6), force)        # noqa: E731
    rec = Recorder(robot)
    held = {}
    n_settle = int(round(SETTLE_TIME / DT))

    cfc_setpoint = []                          # per period: the CFC's set-point and feed-forward, the larger
    stiffness = {}                             # the stiffness met in B and the P part's in D (contact_margin)

    def settle_then_press(k_, loop, sim):
        if k_ == n_settle:                     # the floor in place, then M103
            sim.place_obstacle(0, (x[0], x[1], lowest - gap))
            loop.set_parameter("hybrid_force_controller", "enabled", True)
        if loop.failure is not None:
            held.setdefault("reason", loop.failure)
        if k_ > 0 and loop.contact is not None and hasattr(loop.contact, "f_set"):
            cfc_setpoint.append(np.maximum(loop.contact.f_set, loop.contact.f_ff))   # (of period k_ - 1, as rec's rows)
        if loop.hpfc is not None and loop.hpfc.control.k_contact is not None and "k_met" not in stiffness:
            stiffness.update(k_met=float(loop.hpfc.control.k_contact), k_pid=float(loop.hpfc.control.k_pid),
                             limits=loop._limits)      # (the distribution's f_min, f_max of that period)
    rec.hooks += [settle_then_press, _settled_watch(rec, F_d)]
    params = control_loop_params(robot, hpfc=hpfc, hpfc_enabled=False)
    v_approach = HybridForceControl(robot, DT, hpfc).approach_speed(F_d)      # (below v_max on stiff floors)
    duration = SETTLE_TIME + params.transfer_time + gap / v_approach + CONTACT_TIME
    config = sim_config(spec, obstacles=(floor,))
    ok = recorded_run(robot, rec, source, duration, params, x0=x, config=config)
    refused = next((s.hpfc for s in rec.rows["state"] if s.hpfc is not None and s.hpfc.refused), None)
    if refused is not None:
        # the controller refuses contact where the pose's capacity leaves less than it can regulate
        # (HybridForceControl.minimum_contact_force; docs/validation.md, "Contact after session 13")
        from cdpr_control.control.hybrid_force_control import refusal_message
        F_min = HybridForceControl(robot, DT, hpfc).minimum_contact_force()
        return CaseResult(spec, {"contact_capacity_N": contact_capacity(robot, x), "F_d_requested_N": F_d}, {},
                          "refused", refusal_message(refused, x, F_min))
    t, F, f = rec.array("t"), rec.array("w_contact")[:, 2], rec.array("f")
    states = np.array([s.hpfc.state for s in rec.rows["state"]])
    F_c = np.array([s.hpfc.F for s in rec.rows["state"]])          # the controller's contact force
    touched = np.flatnonzero(F > 0.0)
    metrics = dict.fromkeys(("overshoot_percent", "settling_s", "steady_error_percent", "steady_error_true_percent",
                             "slack_s", "setpoint_above_f_max_N", "distribution_above_f_max_N"), float("nan"))
    metrics["time_in_B_s"] = float(np.count_nonzero(states == "B") * DT)
    metrics["contact_capacity_N"] = capacity = contact_capacity(robot, x)
    metrics["impact_s"] = float(t[touched[0]]) if len(touched) else float("nan")
    # beyond the pose's capacity the controller regulates a limited F_d (the state's; the lead's
    # decision of session 12): the case is judged on it, with the same bands
    F_d_run = regulated_force(rec, F_d)
    metrics["F_d_regulated_N"] = F_d_run
    r_c = rotation_matrix(x[3:]) @ np.asarray(centre) - np.array([0.0, 0.0, radius])    # the tool's lowest point
    metrics.update(contact_loop_margins(robot, hpfc, stiffness, x, r_c, F_d_run, plant_of(robot, config).robot.drive))
    if len(touched) and ok:
        i, n = touched[0], int(STEADY_WINDOW / DT)
        # overshoot and slack on the simulator's true forces; settling and steady error on the
        # control error e_F = F_d - F of the force the robot measures (section 5.1.3, as table 5.2);
        # the true force's steady error beside it, reported: the sensors' calibration, not the control
        acting = ~np.array([any(fault.holds for fault in s.faults) for s in rec.rows["state"]])
        f_d = np.array([s.f_d for s in rec.rows["state"]])          # the force distribution's set-point
        # what reaches the drives: the CFC's set-point and feed-forward (ContactCableForceControl
        # clips them to the distribution's limits since session 13; the distribution's least-violating
        # forces beside it, reported: distribution_above_f_max_N)
        f_cfc = np.array(cfc_setpoint[:len(t)]) if len(cfc_setpoint) >= len(t) else f_d
        metrics.update(overshoot_percent=criteria.overshoot_percent(F[i:], F_d_run),
                       settling_s=criteria.settling_time(t[i:], F_c[i:], F_d_run),
                       steady_error_percent=criteria.steady_error_percent(F_c[i:], F_d_run, n),
                       steady_error_true_percent=criteria.steady_error_percent(F[i:], F_d_run, n),
                       slack_s=criteria.slack_time(f[i:], robot.cable.f_min, DT),
                       setpoint_above_f_max_N=criteria.above_limit(f_cfc[i:][acting[i:]], robot.cable.f_max),
                       distribution_above_f_max_N=criteria.above_limit(f_d[i:][acting[i:]], robot.cable.f_max))
    note = "" if len(touched) else "never touched the floor"
    if capacity < F_d:
        note = "; ".join(n for n in (note, f"F_d beyond the pose's contact capacity ({capacity:.4g} N within the "
                                           f"planned force limits)") if n)
    if F_d_run < F_d:
        note = "; ".join(n for n in (note, f"the controller limited F_d to {F_d_run:.4g} N (its capacity "
                                           f"{_controller_capacity(rec):.4g} N), judged on that") if n)
    held_text = rec.held or (f"held by the force watch: {held['reason']}" if "reason" in held else None)
    return judge(spec, metrics, not ok, note or (f"diverged at {rec.diverged_at:.3f} s" if not ok else ""), held_text)


def contact_loop_margins(robot, hpfc: HPFCParams, stiffness: dict, x, r_c, F_d: float, plant_drive=None) -> dict:
    """The contact force loop's margins in D (:func:`cdpr_control.analysis.contact_margin.case_margins`:
    the platform at x pressing F_d at r_c, the stiffness B measured (k_met), the one the P part
    divided by (k_pid)) with the robot file's drive (what the controller knows), and the gain margin
    with the plant's own drive (``plant_drive``, the mismatched plant's dead time and T_1):
    reported, not judged (NaN where D was not reached). docs/validation.md, "Contact margin
    (session 14)"."""
    from cdpr_control.analysis.contact_margin import case_margins
    out = dict.fromkeys(("k_met_N_per_m", "k_pid_N_per_m", "contact_gain_margin_dB", "contact_phase_margin_deg",
                         "contact_phase_crossover_Hz", "contact_gain_margin_plant_dB"), float("nan"))
    if stiffness.get("k_met", 0.0) > 0.0:
        f_min, f_max = stiffness["limits"] if stiffness.get("limits") is not None else (robot.cable.f_min, robot.cable.f_max)
        args = (robot, hpfc, DT, x, (0.0, 0.0, -1.0), F_d, r_c, stiffness["k_met"], stiffness["k_pid"] or hpfc.K_p,
                f_min, f_max)
        m = case_margins(*args)
        out.update(k_met_N_per_m=stiffness["k_met"], k_pid_N_per_m=stiffness["k_pid"], contact_gain_margin_dB=m.gain_dB,
                   contact_phase_margin_deg=m.phase_deg, contact_phase_crossover_Hz=float(m.f_phase))
        if plant_drive is not None:
            out["contact_gain_margin_plant_dB"] = case_margins(*args, drive=plant_drive).gain_dB
    return out


def regulated_force(rec: Recorder, F_d: float) -> float:
    """The contact force [N] the controller regulated: its state's F_d in the last period of D (the
    requested F_d, or less where the pose's capacity limited it), F_d where it never reached D."""
    for s in reversed(rec.rows["state"]):
        if s.hpfc is not None and s.hpfc.state == "D":
            return float(s.hpfc.F_d)
    return F_d


def _controller_capacity(rec: Recorder) -> float:
    """The pose's contact capacity [N] the controller computed (its state's), NaN where it did not."""
    for s in reversed(rec.rows["state"]):
        if s.hpfc is not None and np.isfinite(s.hpfc.capacity):
            return float(s.hpfc.capacity)
    return float("nan")


def contact_capacity(robot, x) -> float:
    """The largest force [N] the platform can press down at x at rest with cable forces within the
    shipped distribution's limits (the parameter file's f_min, the robot's f_max): the controller's
    own :func:`cdpr_control.control.hybrid_force_control.contact_capacity` (an LP: the weight's
    wrench plus the contact's reaction F e_z wrench-feasible (2.40)) for a press along -e_z.
    Reported: a contact beyond it asks forces the distribution cannot plan (it overloads or leaves a
    cable below its planned f_min) whatever the controller does, which since session 12 limits the
    force it regulates (``F_d_regulated_N``, docs/validation.md, "Beyond the pose's contact capacity")."""
    from cdpr_control import kernels
    from cdpr_control.control import hybrid_force_control
    from cdpr_control.model.dynamics import gravity_wrench
    from cdpr_tools.validate.grid import planned_f_min

    x = np.asarray(x, dtype=float)
    AT, = kernels.inverse_kinematics_fields(robot, x, "AT")
    f_max = np.asarray(robot.cable.f_max, dtype=float) * np.ones(robot.m)
    return hybrid_force_control.contact_capacity(AT, gravity_wrench(robot, x), np.array([0.0, 0.0, -1.0]),
                                                 planned_f_min(robot), f_max)


def _settled_watch(rec: Recorder, F_d: float):
    """A hook ending the run (:class:`Done`) once the controller's contact force (what settling is
    judged on) has been within the 2 % band for SETTLED_HOLD s and for STEADY_WINDOW s at least
    after the impact (the first true contact)."""
    n_hold, n_steady = int(SETTLED_HOLD / DT), int(STEADY_WINDOW / DT)
    state = {"impact": None, "inside": 0}

    def watch(k, loop, sim):
        w = rec.rows["w_contact"]
        if not w:
            return
        if state["impact"] is None and w[-1][2] > 0.0:
            state["impact"] = len(w) - 1
        if state["impact"] is not None:
            hpfc = rec.rows["state"][-1].hpfc
            F, F_r = hpfc.F, (hpfc.F_d if hpfc.state == "D" else F_d)     # (the regulated F_d: regulated_force)
            state["inside"] = state["inside"] + 1 if abs(F - F_r) <= 0.02 * F_r else 0
            if state["inside"] >= max(n_hold, n_steady):
                raise Done
    return watch


# ---- (b) hand guiding ---------------------------------------------------------------------------

def _admittance_values(robot_name: str) -> dict:
    """The flat admittance_controller parameters of the robot's file over the library defaults."""
    from cdpr_control.control.admittance import default_parameters

    return {**default_parameters(), **file_section(robot_name, "admittance_controller")}


class Settled:
    """``enable_at`` of :func:`cdpr_sim.hand_guiding.guiding_run`: true in the first period from
    GUIDING_ENABLE on in which the platform's true pose has stayed within SETTLED_BAND of its mean
    over the last SETTLED_WINDOW, or at GUIDING_ENABLE_MAX; ``at`` [s] then, ``settled`` whether it had."""

    def __init__(self):
        self.n = int(round(SETTLED_WINDOW / DT))
        self.poses: list = []
        self.at: float | None = None
        self.settled = False

    def spread(self) -> tuple[float, float]:
        """(largest distance [m], largest angle [rad]) of the window's poses from their mean."""
        x = np.array(self.poses[-self.n:])
        d = x - x.mean(axis=0)
        return float(np.linalg.norm(d[:, :3], axis=1).max()), float(np.abs(d[:, 3:]).max())

    def __call__(self, k, loop, sim) -> bool:
        t = k * DT
        self.poses.append(np.array(sim.output.x[:6], dtype=float))
        if t < GUIDING_ENABLE - 1e-9:
            return False
        self.settled = len(self.poses) >= self.n and all(s <= b for s, b in zip(self.spread(), SETTLED_BAND))
        if self.settled or t >= GUIDING_ENABLE_MAX - 1e-9:
            self.at = t
            return True
        return False


class _AfterEnable:
    """A Recorder hook: the hand's ``segments`` (times from the enable), the loop's user wrench of each
    period recorded (``w_user``, aligned with the recorder's rows), the run ended (Done) ``duration`` s
    after the enable."""

    def __init__(self, settled: Settled, segments, duration: float):
        self.settled, self.segments, self.duration = settled, list(segments), duration
        self.hand = None
        self.w_user: list = []

    def __call__(self, k, loop, sim):
        from cdpr_sim.hand import Hand

        if k > 0:
            w = getattr(loop.force, "w_user", None)
            self.w_user.append(np.zeros(6) if w is None else np.array(w, dtype=float))
        if self.settled.at is None:
            return
        if self.hand is None:
            self.hand = Hand([replace(s, t=s.t + self.settled.at) for s in self.segments])
        if k * DT >= self.settled.at + self.duration - 1e-9:
            raise Done
        self.hand.apply(sim)


def _guided(spec: CaseSpec, robot, overrides: dict, segments, duration: float):
    """The library's hand-guiding run (:func:`cdpr_sim.hand_guiding.guiding_run`: the shipped
    configuration, zones about the pose shrunk to the WFW where they leave it) at the pose, switched
    on once the platform has settled (:class:`Settled`), the hand pushing ``segments`` (their times
    from the enable), ``duration`` s from the enable -> (recorder, GuidingRecord or None, ok). The
    friction compensation has the case's friction (``spec.friction``: identified on the plant or
    the robot file's, :mod:`cdpr_tools.validate.friction`)."""
    from cdpr_sim.hand_guiding import guiding_run

    from cdpr_tools.validate.friction import loop_params

    settled = Settled()
    after = _AfterEnable(settled, segments, duration)
    rec = Recorder(robot, hooks=[after])
    clipping = _fitted(spec, robot, overrides)[3]          # ValueError where nothing fits, before running
    try:
        guiding_run([], GUIDING_ENABLE_MAX + duration + DT, overrides, robot_name=spec.robot, before_step=rec,
                    x_hold=spec.x, config=sim_config(spec), enable_at=settled,
                    loop_params=loop_params(spec.robot, spec.friction))
    except Diverged:
        return rec, None, False
    except Done:
        pass
    n = len(rec.rows["t"])
    return rec, GuidingRecord(settled.at, settled.settled, np.array(after.w_user[:n]), clipping), True


@dataclass
class GuidingRecord:
    """What :func:`_guided` adds to its recorder."""

    enabled_at: float        # s: hand guiding switched on
    settled: bool            # the platform had settled then (else GUIDING_ENABLE_MAX was reached)
    w_user: np.ndarray       # (N, 6) the user's wrench w_Adm the loop had, per recorded row (0 while off)
    clipping: object         # the zones' Clipping at the pose (None: as configured)

    def since(self, rec: Recorder) -> np.ndarray:
        """The recorder's times [s] from the enable."""
        return rec.array("t") - self.enabled_at


def _fitted(spec: CaseSpec, robot, overrides: dict):
    """:func:`~cdpr_control.control.admittance.fitted_settings` of the shipped admittance section with
    ``overrides``, the zones about the pose (as guiding_run sets them up)."""
    from cdpr_control.control.admittance import fitted_settings
    from cdpr_control.control.params import shipped_configuration

    origin = (np.asarray(spec.x, dtype=float) - robot.home).tolist()
    values = {**shipped_configuration(robot).admittance, "zones.origin": origin, **overrides}
    return fitted_settings(values, robot)


@dataclass(frozen=True)
class PushCapacity:
    """What a user can push at a pose (:func:`push_scale`)."""

    scale: float             # largest k in [0, 1]: k * the nominal push keeps the hand's share within the reserve
    share_N: float           # the nominal push's share max_i |Δf_i| [N], Δf = (A^T)^+ h
    margin_N: float          # t [N] of the model's wrench with the nominal push (-inf: no solution within the limits)

    @property
    def beyond(self) -> bool:
        """The pose carries less than PUSH_MIN_SCALE of the nominal push: a *beyond capacity* case."""
        return self.scale < PUSH_MIN_SCALE


def push_scale(robot, x, push, tol: float = 1e-4) -> PushCapacity:
    """The largest share k in [0, 1] of the hand's wrench ``push`` (6,) [N, N m] for which the hand's
    share of the cable forces stays within the reserve the pose leaves: max_i |Δf_i(k h)| <=
    RESERVE_SHARE * t(w + k h) / RESERVE_RING, Δf = (A^T)^+ h
    (:func:`~cdpr_control.control.force_setpoint.user_forces`)
    and t the largest margin (:func:`~cdpr_control.control.force_setpoint.largest_margin`) of the
    model's static wrench w (2.33) with the push, within the distribution's planned limits (the
    parameter file's f_min, the robot's f_max): exactly the hand's reserve r = min(2 share, 0.7 t)
    the force set-point plans while the user pushes, RESERVE_RING times the share (the release's
    swing, not only its static change: docs/admittance.md), untruncated. t is concave
    in the wrench and the share linear in k, so the condition holds on an interval from k = 0 (where
    the pose leaves any margin): bisection to ``tol``. k = 0 where the pose leaves no margin at all."""
    from cdpr_control import kernels
    from cdpr_control.control.force_setpoint import RESERVE_RING, RESERVE_SHARE, largest_margin, user_forces
    from cdpr_tools.validate.grid import planned_f_min

    x, h = np.asarray(x, dtype=float), np.asarray(push, dtype=float)
    f_min = planned_f_min(robot)
    f_max = np.asarray(file_section(robot.file.stem, "force_distribution").get("f_max", robot.cable.f_max),
                       dtype=float) * np.ones(robot.m)
    w = kernels.platform_wrench(robot, x, np.zeros(6), np.zeros(6))
    AT, = kernels.inverse_kinematics_fields(robot, x, "AT")
    share = float(np.abs(user_forces(AT, h)).max())

    def within(k: float) -> bool:
        return RESERVE_RING * k * share <= RESERVE_SHARE * largest_margin(AT, w + k * h, f_min, f_max)

    margin = largest_margin(AT, w + h, f_min, f_max)
    if within(1.0):
        return PushCapacity(1.0, share, margin)
    lo, hi = 0.0, 1.0
    if not within(lo):
        return PushCapacity(0.0, share, margin)
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if within(mid) else (lo, mid)
    return PushCapacity(lo, share, margin)


def guiding_case(spec: CaseSpec) -> CaseResult:
    """Hand guiding switched on at the pose once the platform has settled after the start-up
    (:class:`Settled`; as a user switches it on a robot standing still): at rest with nobody pushing
    for REST_TIME, then a push in the variant's direction, held, released; then the eigenfrequency
    of (5.12) with the robot's EIGEN zone (:func:`_eigen_case`). Zones that would leave the WFW at
    the pose are shrunk to fit, and the note says so. Both runs compensate the pulley friction of
    ``spec.friction`` (the sweep: identified on the case's plant, as a user runs the robot); the
    note says which.

    The push is what a user can legitimately apply at the pose: PUSH_SHARE w_max scaled by
    :func:`push_scale` (the hand's share of the cable forces within the pose's reserve). Where that
    is below PUSH_MIN_SCALE the pose is *beyond capacity*: the nominal push is applied, the lowest
    cable is reported, not judged, and the case passes when safety holds (a hold of the loop from
    the push on is then the safe reaction, not a failure; the slack while held and still pushed is
    reported as ``held_slack_s`` and ``held_min_force_N``, not judged). Every case: no cable below
    SAFETY_SLACK_SHARE f_min for more than 50 ms while the loop does not hold (``safety_slack_s``),
    no force set-point above f_max while it does not hold, every cable back within [f_min, f_max]
    within ``recovery_s`` of the release."""
    from cdpr_control.control.admittance_zones import per_axis
    from cdpr_sim.hand import Segment

    from cdpr_tools.validate.friction import text as friction_text

    robot = load_robot(spec.robot)
    w_max = per_axis(_admittance_values(spec.robot)["w_max"], "w_max")
    direction = np.asarray(spec.variant["direction"], dtype=float)
    nominal = np.r_[PUSH_SHARE * w_max[0] * direction / np.linalg.norm(direction), np.zeros(3)]
    capacity = push_scale(robot, spec.x, nominal)
    push = nominal if capacity.beyond else capacity.scale * nominal
    t_push, t_release = REST_TIME, REST_TIME + PUSH_HOLD            # s from the enable
    segments = [Segment(t_push, tuple(push), "ramp", PUSH_RISE), Segment(t_push + PUSH_RISE, tuple(push), "step"),
                Segment(t_release, release=True)]
    try:
        rec, g, ok = _guided(spec, robot, {}, segments, t_release + PUSH_AFTER)
    except ValueError as exc:
        return CaseResult(spec, {}, {}, "refused", f"hand guiding refused at this pose: {exc}")
    notes = [friction_text(spec.friction)] + ([] if g is None or g.clipping is None else [g.clipping.text()])
    if capacity.beyond:
        notes.append(f"beyond capacity: the pose carries {100 * capacity.scale:.3g} % of the {np.linalg.norm(nominal):.3g} N "
                     f"push (share {capacity.share_N:.3g} N, margin {capacity.margin_N:.3g} N pushed): pushed "
                     "with it, judged on safety")
    elif capacity.scale < 1.0:
        notes.append(f"push scaled to {100 * capacity.scale:.3g} % ({np.linalg.norm(push):.3g} N) by the pose's reserve")
    margin_key = "push_min_force_N" if capacity.beyond else "push_force_margin_N"
    metrics = {"push_N": float(np.linalg.norm(push[:3])), "push_scale": capacity.scale,
               "beyond_capacity": float(capacity.beyond)}
    metrics.update(dict.fromkeys(("enabled_at_s", "rest_motion_mm", "rest_wrench_percent", margin_key,
                                  "push_min_force_N", "safety_slack_s", "setpoint_above_f_max_N", "held_slack_s", "held_min_force_N",
                                  "recovery_s"), float("nan")))
    held = rec.held
    if ok:
        t = g.since(rec)
        on = t > 0.0
        rest = on & (t <= REST_TIME)
        f = rec.array("f")
        # while the loop holds, the joint command restores the force watch's last safe forces: the
        # live set-point reaches no drive, and the robot stands braked on its path
        acting = np.array([s is None or not any(fault.holds for fault in s.faults) for s in rec.rows["state"]])
        f_d = np.array([np.full(robot.m, np.nan) if s is None else s.f_d for s in rec.rows["state"]])
        slack = criteria.SAFETY_SLACK_SHARE * robot.cable.f_min
        held_pushed = on & ~acting & (t < t_release)
        metrics.update(enabled_at_s=g.enabled_at,
                       rest_motion_mm=criteria.rest_motion_mm(rec.array("x")[rest]),
                       rest_wrench_percent=criteria.wrench_share_percent(g.w_user[rest], w_max),
                       push_min_force_N=float(f[on].min()),
                       safety_slack_s=criteria.slack_time(f, slack, DT, where=on & acting),
                       setpoint_above_f_max_N=criteria.above_limit(f_d[on & acting], robot.cable.f_max),
                       held_slack_s=criteria.slack_time(f, slack, DT, where=held_pushed),
                       held_min_force_N=float(f[held_pushed].min()) if held_pushed.any() else float("nan"),
                       recovery_s=criteria.recovery_time(f[t >= t_release], robot.cable.f_min, robot.cable.f_max, DT))
        if not capacity.beyond:
            metrics["push_force_margin_N"] = float((f[on] - robot.cable.f_min).min())
        if not g.settled:
            notes.append(f"switched on at {g.enabled_at:.3g} s without the platform settled")
        if hold_is_safe_reaction(capacity, _first_hold(rec), g.enabled_at + t_push):
            notes.append(f"the safe reaction: {rec.held}")
            held = None
    else:
        notes.append(f"diverged at {rec.diverged_at:.3f} s")
    eigen, ok_eigen, note, held_eigen = _eigen_case(spec, robot)
    metrics.update(eigen)
    notes += [note] if note else []
    held = held or (f"in the eigenfrequency run: {held_eigen}" if held_eigen else None)
    return judge(spec, metrics, not (ok and ok_eigen), "; ".join(notes), held)


def hold_is_safe_reaction(capacity: PushCapacity, hold_at: float | None, t_push: float) -> bool:
    """A hold of the loop at ``hold_at`` [s] (None: none) is the safe reaction to the push, not a
    failure: the pose is beyond capacity and the hold came once the push had begun (``t_push``)."""
    return capacity.beyond and hold_at is not None and hold_at >= t_push


def _first_hold(rec: Recorder) -> float | None:
    """The time [s] of the first period in which the loop held (a holding fault), None if never."""
    for t, state in zip(rec.rows["t"], rec.rows["state"]):
        if state is not None and any(f.holds for f in state.faults):
            return float(t)
    return None


def _eigen_case(spec: CaseSpec, robot) -> tuple[dict, bool, str, str | None]:
    """The robot's EIGEN (c, d, m) on x in a rest sphere of EIGEN_ZONE, pushed along x for
    EIGEN_PUSH s once the tare is taken, and released; the ground truth's oscillation fitted over EIGEN_WINDOW from 50 ms
    after the release, against (5.12) -> (metrics, ok, note, the run's hold or None)."""
    from cdpr_control.control.admittance import damped_eigenfrequency
    from cdpr_sim.hand import Segment

    e = EIGEN[spec.robot]
    c, d, m = e["cdm"]
    rest = _admittance_values(spec.robot)
    overrides = {**EIGEN_ZONE, **{f"zones.rest.{k}": [v] + list(rest[f"zones.rest.{k}"][1:])
                                  for k, v in zip("cdm", (c, d, m))}}
    # pushed 50 ms after the tare (w_init, averaged over tare_time after switching on): a push
    # within it would be tared away and read as a user wrench the other way after the release
    t_push = float(rest["tare_time"]) + 0.05                     # s from the enable
    release = t_push + EIGEN_PUSH
    metrics = {"eigenfrequency_Hz": float("nan"), "eigenfrequency_error_percent": float("nan")}
    try:
        push = _eigen_push(spec, robot, overrides, e["push"])
        rec, g, ok = _guided(spec, robot, overrides, [Segment(t_push, (push, 0, 0, 0, 0, 0), "rectangle", EIGEN_PUSH)],
                             release + 0.05 + EIGEN_WINDOW)
    except ValueError as exc:
        return metrics, True, f"eigenfrequency not measured, its zones refused: {exc}", None
    if not ok:
        return metrics, False, f"diverged in the eigenfrequency run at {rec.diverged_at:.3f} s", rec.held
    t, x = g.since(rec), rec.array("x")
    sel = t > release + 0.05
    f_exp = criteria.fitted_frequency(t[sel], x[sel, 0])
    f_theo = damped_eigenfrequency(c, d, m)
    metrics.update(eigenfrequency_Hz=f_exp, eigenfrequency_error_percent=100.0 * (f_exp - f_theo) / f_theo)
    note = "" if g.clipping is None else "eigenfrequency zones: " + g.clipping.text()
    return metrics, True, note, rec.held


def _eigen_push(spec: CaseSpec, robot, overrides: dict, push: float) -> float:
    """The eigenfrequency run's push [N]: ``push``, its part above the dead band scaled with the
    rest sphere where the zones are shrunk to the WFW at the pose (the oscillation's amplitude is
    proportional to it: it stays inside the shrunk sphere, the zone whose c, d, m are measured)."""
    from cdpr_control.control.admittance_zones import per_axis

    params, _, _, clipping = _fitted(spec, robot, overrides)
    if clipping is None:
        return push
    dead_band = per_axis(params.user.dead_band, "dead_band")[0]
    return dead_band + clipping.scale * (push - dead_band)


# ---- (c) payload --------------------------------------------------------------------------------

def _payload_run(spec: CaseSpec, robot, config: str, mass: float, after_rest=None):
    """A payload step at the pose: REST tared empty, the step over PAYLOAD_RAMP (cosine, as a load
    put down by hand: an instantaneous step rings the lightly damped vertical mode), PAYLOAD_DWELL
    after it; the plant's cables settled to the unloaded rest they carry the payload from
    (:func:`settle_plant` each period until the step) -> (recorder, m_c (N,), ok, hold): ok False
    when it diverged; hold the force watch's first hold (control.safety.ForceWatch, on by default)
    as (t [s], reason), else None: the figures of a held run are those of the held robot, not of
    the controller. ``after_rest(recorder)`` True, asked once the unloaded rest is recorded, ends
    the run there (what the rest showed is all the caller needs)."""
    from cdpr_control.control.load_compensation import LoadCompensationParams, LoadCompensationStage
    from cdpr_tools.identify.load_steps import CONFIGS, loop_params
    from cdpr_tools.validate.friction import with_friction

    x = np.asarray(spec.x, dtype=float)
    from cdpr_tools.validate.settlement import lc_values as settlement_values

    lc_values = {k: v for k, v in file_section(spec.robot, "load_compensation").items()
                 if k in LoadCompensationParams.__dataclass_fields__}
    lc_values.update(settlement_values(spec.settlement))      # identified on the plant: also in the pose
    params = LoadCompensationParams(**{**lc_values, "enabled": CONFIGS[config][2]})
    stage = LoadCompensationStage(robot, DT, params, feed_force_setpoint=CONFIGS[config][3])
    n_rest, n_ramp = int(round(PAYLOAD_REST / DT)), int(round(PAYLOAD_RAMP / DT))
    m_c, held, settlement, slack = [], [], [], []
    warning = []

    def put_down(k, loop, sim):
        if after_rest is not None and k == n_rest + 1 and after_rest(rec):
            raise Done               # the rows up to t = REST recorded: the same rest as a whole run's
        if k > 0:
            m_c.append(stage.compensation.m_c)
            # for the diagnosis (sag_diagnosis): the plant's settlement, a truth the controller
            # does not see, and the load compensation's own diagnostic of slack cables
            settlement.append(np.array(sim.settlement.s, dtype=float))
            slack.append(stage.compensation.slack_cables)
            if not warning and (problem := stage.compensation.slack_problem()):
                warning.append(f"{problem} (from {float(sim.output.t):.2f} s)")
            if loop.failure is not None and not held:
                held.append((float(sim.output.t), loop.failure))
        if k <= n_rest:
            settle_plant(sim)                    # the plant settles under the payload only
        i = k - n_rest
        if 0 <= i < n_ramp + 1:
            sim.set_payload(mass * (0.5 * (1.0 - np.cos(np.pi * min(i + 1, n_ramp) / n_ramp))))

    # the pulley friction compensated as the case's record says (the sweep: identified on the plant,
    # validate.friction): (4.4) reads the friction-compensated forces
    params = with_friction(loop_params(config, spec.robot), spec.friction)
    if config == REFERENCE:
        # the reference measures the sag IK-only control leaves; its lower cables go slack under a
        # payload (the Mini's at any payload worth compensating), which the force watch would hold
        params = replace(params, safety=replace(params.safety, force_watch=False))
    rec = Recorder(robot, [put_down])
    ok = recorded_run(robot, rec, hold(x), PAYLOAD_REST + PAYLOAD_RAMP + PAYLOAD_DWELL, params,
                      x0=x, offset_stages={"load_compensation": stage}, config=sim_config(spec))
    rec.settlement = np.array(settlement, dtype=float).reshape(-1, robot.m)
    rec.slack_cables = np.array(slack, dtype=int)
    rec.lc_warning = warning[0] if warning else None
    return rec, np.array(m_c, dtype=float), ok, (held[0] if held else None)


def settle_plant(sim) -> None:
    """The simulated plant's cables settled to the forces they carry now (section 4.1.3), their
    lasting growth s kept: f_settled becomes the force at which the plant's settlement law's target
    is the present s, so s grows again only under forces above the present ones.

    The payload case calls it in every period of the unloaded rest, so that the plant at the step is
    one settled to the rest it is put on, as a robot that has stood there long (the state the
    settlement run identifies the ratio from, ``record_settlement_run`` under IK-only control, and
    the load compensation's model assumes from its tare on, ``SettlementModel.reset``), and settles
    under the payload's forces only. The simulator's cables settle from the forces of its first
    measurement (the gravity-only state of a fresh start, ``Simulator.reset``), and force control
    raises them at start-up to its distribution's pre-tension (on the Mini 2-12 N per cable, against
    the 0.1-3 kg payloads' 1-3 N), under which the plant went on settling with its T (2 s) through
    the whole dwell: up to 0.4 mm per cable, a drift of the platform of +0.04 to +0.09 mm at the
    Mini's seed 2 poses with no payload at all, which the sag counted as the payload's; and keeping
    the start-up's force peaks as the cables' history instead (they settle only above the highest
    force of the rest) made the payload's settlement depend on the start-up's overshoot
    (docs/validation.md, "The Mini's sag after session 15")."""
    from cdpr_control.model import cable

    st = sim.settlement
    st.settle(sim.output.f, cable.total_free_length(sim.robot, np.asarray(sim.drives.theta, dtype=float) + st.s))


def _sag(rec, twin=None) -> float:
    """Static z error [m] at the end of the dwell: against the unloaded twin's at the end of its
    dwell (``twin``: the same run with no payload, :func:`_payload_result`), or, without one, against
    the run's own at the end of the unloaded rest."""
    z = rec.array("x")[:, 2]
    n = int(SAG_WINDOW / DT)
    if twin is not None:
        return float(z[-n:].mean() - twin.array("x")[-n:, 2].mean())
    t = rec.array("t")
    rest = (t > PAYLOAD_REST - SAG_WINDOW) & (t <= PAYLOAD_REST)
    return float(z[-n:].mean() - z[rest].mean())


def _end_window(t) -> np.ndarray:
    """The dwell's last window (SAG_WINDOW) of the sag, as a mask of t."""
    t = np.asarray(t, dtype=float)
    return t > t[-1] - SAG_WINDOW + 0.5 * DT


def _controller_z(rec) -> np.ndarray | None:
    """The controller's own z [m] per period (the forward kinematics' pose), None where the run
    recorded no loop state."""
    states = rec.rows.get("state", [])
    if len(states) != len(rec.rows["t"]) or any(s is None for s in states):
        return None
    return np.array([s.x[2] for s in states])


def settlement_sag(robot, x, s) -> float:
    """z [m] by which cable length growths s (m,) [m] at constant forces move the platform at x:
    the z part of the least-squares pose change J dx = s, J = dq/dx of the inverse kinematics (2.2)
    by central differences (a settled cable is longer by s_i at the same force; force control holds
    the forces, so the platform moves rigidly)."""
    from cdpr_control.model.kinematics import inverse_kinematics

    x = np.asarray(x, dtype=float)
    h = 1e-6
    J = np.column_stack([(inverse_kinematics(robot, x + h * e).q - inverse_kinematics(robot, x - h * e).q) / (2 * h)
                         for e in np.eye(6)])
    return float(np.linalg.lstsq(J, np.asarray(s, dtype=float), rcond=None)[0][2])


def sag_diagnosis(robot, x, rec, twin) -> dict:
    """Where a run's sag [mm] comes from (reported, not judged; NaN where the run did not record it),
    each against the unloaded twin's at the same time (``twin``, as the sag itself):
    ``sag_seen_mm``, the sag of the controller's own pose (the forward kinematics': what its OSPC
    can act on); ``sag_unseen_mm``, the rest of the true sag, which the controller cannot see (the
    forward kinematics' error under the payload); ``settlement_sag_mm``, the part of the true sag
    the plant's cable settlement (section 4.1.3) accounts for (:func:`settlement_sag` of its growth,
    a truth of the simulator); ``sag_drift_mm``, the sag's change over the dwell's last second
    (window mean against the window one second before: a transient still under way, not a static
    sag)."""
    t, z, z0 = rec.array("t"), rec.array("x")[:, 2], twin.array("x")[:, 2]
    nan = float("nan")
    out = dict.fromkeys(("sag_seen_mm", "sag_unseen_mm", "settlement_sag_mm", "sag_drift_mm"), nan)
    if not len(t) or len(z0) != len(t):
        return out
    end = _end_window(t)
    earlier = (t > t[-1] - 1.0 - SAG_WINDOW + 0.5 * DT) & (t <= t[-1] - 1.0 + 0.5 * DT)
    dz = z - z0
    out["sag_drift_mm"] = 1e3 * float(dz[end].mean() - dz[earlier].mean())
    z_c, z_c0 = _controller_z(rec), _controller_z(twin)
    if z_c is not None and z_c0 is not None:
        seen = z_c[end].mean() - z_c0[end].mean()
        out["sag_seen_mm"] = 1e3 * float(seen)
        out["sag_unseen_mm"] = 1e3 * float(dz[end].mean() - seen)
    s, s0 = getattr(rec, "settlement", None), getattr(twin, "settlement", None)
    if s is not None and s0 is not None and len(s) == len(t) and len(s0) == len(t):
        out["settlement_sag_mm"] = 1e3 * settlement_sag(robot, x, s[end].mean(axis=0) - s0[end].mean(axis=0))
    return out


def diagnosis_note(metrics: dict) -> str:
    """The note of a sag out of its band: how much of it the controller sees, the plant's settlement,
    and the drift ("" without a recorded controller pose)."""
    m = metrics
    if not np.isfinite(m.get("sag_seen_mm", float("nan"))):
        return ""
    text = (f"of the residual {m['sag_mm']:.3g} mm the controller sees {m['sag_seen_mm']:.3g} mm, "
            f"{m['sag_unseen_mm']:.3g} mm is unseen by its forward kinematics")
    if np.isfinite(m["settlement_sag_mm"]) and abs(m["settlement_sag_mm"]) >= 0.05 * abs(m["sag_mm"]):
        text += f" (the plant's cable settlement: {m['settlement_sag_mm']:.3g} mm)"
    return text + f"; z moved {m['sag_drift_mm']:+.3g} mm over the last second"


def static_accuracy(rec, z_d: float) -> float:
    """The platform's static position accuracy in z [m] with no payload: the RMS of the controller's
    own z error, the forward kinematics' z against the set-point z_d, over the end of the unloaded
    rest (SAG_WINDOW before the payload); the true z where the run recorded no loop state. It is
    what force control still moves the platform by during the dwell whatever the payload (the
    convergence after the start-up, the OSPC's integral part: measured up to 0.9 mm at the IPAnema 3,
    0.13 mm at the Mini, docs/validation.md "Payload after session 10") and its noise; the forward
    kinematics' constant offset on a mismatched plant (its anchors) is not in it, as it does not
    move the platform (see :func:`sag_resolution`)."""
    t = rec.array("t")
    rest = np.flatnonzero((t > PAYLOAD_REST - SAG_WINDOW) & (t <= PAYLOAD_REST))
    if not len(rest):
        return float("nan")
    states = rec.rows["state"]
    if len(states) == len(t) and all(states[i] is not None for i in rest):
        z = np.array([states[i].x[2] for i in rest])
    else:
        z = rec.array("x")[rest, 2]
    return float(np.sqrt(np.mean((z - z_d) ** 2)))


def sag_resolution(accuracy: float, plant: str) -> float:
    """The smallest reference sag [m] whose cut the plant's band can judge: the band lets a share
    1 - cut of the reference remain, and a residual below the static accuracy (:func:`static_accuracy`)
    is not resolved, so the cut in percent means something only where (1 - cut) |sag_ref| >= accuracy,
    i.e. |sag_ref| >= accuracy / (1 - cut) (10 accuracies on the nominal plant's 90 %, 6.7 on the
    default plant's 85 %). Below it the case is judged on the residual itself: within the accuracy."""
    return accuracy / (1.0 - criteria.SAG_CUT[plant].lo / 100.0)


def planned_capacity(robot, x) -> float:
    """The largest payload [kg] the shipped force distribution holds at rest at x: the static
    capacity (:func:`cdpr_control.motion.program_check.payload_capacity`) with the distribution's
    f_min of the parameter file (150 N on the IPAnema 3, 7.5 N on the Mini; the robot files' 100 N
    and 5 N are the cables' limits, which the distribution keeps a margin above). A payload beyond
    it is one the shipped configuration cannot distribute at all, so 100 % of the robot-limit
    capacity was a step the controllers could not carry by construction."""
    from cdpr_control.motion.program_check import payload_capacity
    from cdpr_tools.validate.grid import planned_f_min

    planned = replace(robot, cable=replace(robot.cable, f_min=planned_f_min(robot)))
    return payload_capacity(planned, x)


def dynamic_capacity(robot, x) -> float:
    """The largest payload [kg] that can be put down at x, at any speed, without the shipped
    distribution's limits being crossed by the cables' dynamic response: the planned static
    capacity (:func:`planned_capacity`) over DYNAMIC_LOAD_FACTOR. A payload put down moves the
    lightly damped platform like a load on an undamped oscillator, whose peak response to a load
    rising monotonically is at most twice the static one (and reaches it for a sudden step); the
    platform's own weight is static, so the forces stay within what the static distribution holds
    with twice the payload. 100 % of the static capacity is not carried dynamically: some cable
    carries f_max once it rests, and the step's overshoot exceeds it (docs/validation.md, payload)."""
    return planned_capacity(robot, x) / DYNAMIC_LOAD_FACTOR


def payload_case(spec: CaseSpec) -> list[CaseResult]:
    """Payload step of the variant's fraction of the pose's dynamic capacity under the shipped
    configuration (:func:`dynamic_capacity`) under each of PAYLOAD_CONTROLLERS
    (force_control: CFC + OSPC with the identified payload in the force set-point, the shipped
    graph; ik_lc: IK-only with load compensation), one result each, and under IK-only without
    compensation (the reference sag). Estimate error from 1 s after the step began; sag cut
    against the reference, each controller's sag against its unloaded twin (:func:`_payload_result`),
    the reference's against its own rest (IK-only commands fixed lengths: no start-up convergence to
    take out)."""
    from cdpr_control.motion.program_check import payload_capacity

    robot = load_robot(spec.robot)
    capacity = dynamic_capacity(robot, spec.x)
    mass = spec.variant["fraction"] * capacity
    specs = [replace(spec, variant={**spec.variant, "controller": c}) for c in PAYLOAD_CONTROLLERS]
    base = {"capacity_kg": capacity, "capacity_static_kg": DYNAMIC_LOAD_FACTOR * capacity,
            "capacity_robot_limits_kg": payload_capacity(robot, spec.x), "payload_kg": mass}
    if mass < 0.1 * robot.platform.mass:
        return [CaseResult(s, dict(base), {}, "refused", f"payload below a tenth of the platform's mass ({mass:.3g} kg "
                           f"of {robot.platform.mass:.3g} kg: {spec.variant['fraction']:g} of the dynamic capacity "
                           f"{capacity:.3g} kg at this pose, static {DYNAMIC_LOAD_FACTOR * capacity:.3g} kg): no step to make")
                for s in specs]
    # (its force watch off); where its unloaded rest already refuses ik_lc, the payload part of the
    # reference is not needed (a third of the family's CPU at those poses)
    reference, _, ok_ref, _ = _payload_run(spec, robot, REFERENCE, mass,
                                           after_rest=lambda rec: ik_only_slack(robot, rec) is not None)
    unheld = ik_only_slack(robot, reference)
    if unheld:
        # IK-only hangs the platform on fewer cables here: its sag (or rise) is not the elastic
        # sag of the pose, so force control is judged against (4.5)-(4.6) at its own unloaded forces
        sag_reference, note_ref = None, MODEL_REFERENCE_NOTE
    else:
        sag_reference = 1e3 * _sag(reference) if ok_ref else float("nan")
        note_ref = "" if ok_ref else f"the IK-only reference diverged at {reference.diverged_at:.3f} s"
    # IK-only carries the empty platform but not this payload: the watch would hold ik_lc under it
    refusal = unheld or ((ik_only_payload_slack(robot, reference, mass)
                          or ik_only_payload_unconstrained(robot, reference, mass)) if ok_ref else None)
    return [CaseResult(s, dict(base), {}, "refused", refusal) if refusal and s.variant["controller"] == "ik_lc"
            else _payload_result(s, robot, mass, base, sag_reference, note_ref) for s in specs]


def ik_only_payload_slack(robot, reference: Recorder, mass: float) -> str | None:
    """Why IK-only control cannot carry the payload ``mass`` [kg] at this pose (None where it can),
    from the reference run (IK-only under the same payload on the same plant, its force watch off),
    from the step on: a cable below the force watch's lower edge (f_min less its band) for longer
    than the watch's ``force_limit_time``, i.e. where the watch would hold ik_lc under this payload.
    The load compensation cannot change that: x_d,LC is a pose offset, which moves a cable force by
    0.03-0.05 N per mm on the Mini and 0.25-0.34 N per mm on the IPAnema 3 (K_g of (2.22) only,
    docs/load_compensation.md "IK-only + LC refused where IK-only leaves cables slack"), and its
    slack warning comes from a 0.24 s window, after the watch has held (docs/validation.md,
    "Payload after session 13"). So the configuration refuses the payload before any hold, with this
    reason, as force control refuses one beyond its capacity (:func:`dynamic_capacity`)."""
    from cdpr_tools.identify.load_steps import loop_params

    t, f = _measured_forces(reference)                  # what the watch sees
    after = t > PAYLOAD_REST
    if not after.any():
        return None
    safety = loop_params(REFERENCE, robot.file.stem).safety
    f_min, f_max = _cable_limits(robot)
    edge = f_min - safety.force_band * (f_max - f_min)
    below = f[after] < edge
    n_limit = int(round(safety.force_limit_time / DT))
    run = np.zeros(robot.m, dtype=int)
    for k, row in enumerate(below):                      # consecutive periods below the edge, per cable
        run = np.where(row, run + 1, 0)
        if (run > n_limit).any():
            c = int(np.argmax(run))
            low = f[after][: k + 1, c].min()
            return (f"IK-only control cannot carry {mass:.3g} kg at this pose: under it (the IK-only reference, same "
                    f"plant and payload) cable {c + 1} falls to {low:.3g} N, below the force watch's edge "
                    f"{edge[c]:.3g} N for more than {1e3 * safety.force_limit_time:.0f} ms from "
                    f"{t[after][k - n_limit]:.3f} s, where the watch would hold ik_lc; x_d,LC cannot tension a "
                    "cable: carry this payload under force control")
    return None


def ik_only_payload_unconstrained(robot, reference: Recorder, mass: float) -> str | None:
    """Why IK-only control does not constrain the platform under the payload ``mass`` [kg] at this
    pose (None where it does), from the reference run (IK-only under the same payload on the same
    plant): fewer than six cables taut (at or above the load compensation's slack share of f_min,
    ``slack_fraction``, 20 N on the IPAnema 3) for more than UNCONSTRAINED_SHARE of the periods from
    1 s after the step began (the estimate's window) to the end.

    With fewer than six taut cables K_c = A^T K_l A of (2.22) has rank below six: the cable
    lengths no longer fix the pose, the platform hangs as a mechanism that only gravity holds, and
    the compensating offset (4.5)-(4.6) (:func:`cdpr_control.control.load_compensation.secant_offset`)
    and the forward kinematics' pose, which (4.4) differentiates, are not determined by what the
    controller measures. Nothing x_d,LC does tensions a cable; force control keeps them at f_min.
    Measured on the 40-pose grid (docs/validation.md, "Payload after session 18"): at the IPAnema 3's
    ik_lc poses the reference spends 69-95 % of the dwell on fewer than six taut cables at four
    poses (three failing: the platform swings by tens of millimetres for the whole dwell; one, home,
    passing: there the symmetric hang is not excited) and at most 2.4 % at the other four."""
    t, f = _measured_forces(reference)
    after = t >= PAYLOAD_REST + 1.0
    if not after.any():
        return None
    f_slack = _slack_force(robot)
    taut = (f[after] >= f_slack).sum(axis=1)
    share = float(np.mean(taut < 6))
    if share <= UNCONSTRAINED_SHARE:
        return None
    return (f"IK-only control does not constrain the platform under {mass:.3g} kg at this pose: under it (the IK-only "
            f"reference, same plant and payload) fewer than six cables are taut (>= {f_slack.min():.3g} N) for "
            f"{100.0 * share:.0f} % of the dwell (median {int(np.median(taut))} of {robot.m}): the lengths do not fix the "
            "pose, so neither (4.5)-(4.6) nor the forward kinematics is determined; carry this payload under force control")


UNCONSTRAINED_SHARE = 0.5      # of the dwell from 1 s after the step: "most of it"


def _cable_limits(robot) -> tuple[np.ndarray, np.ndarray]:
    """(f_min, f_max) (m,) [N] of the robot's cables."""
    return tuple(np.broadcast_to(np.asarray(v, dtype=float), (robot.m,)) for v in (robot.cable.f_min, robot.cable.f_max))


def _slack_force(robot) -> np.ndarray:
    """(m,) [N]: below it the load compensation takes a cable as slack (its ``slack_fraction`` of f_min)."""
    from cdpr_control.control.load_compensation import LoadCompensationParams

    return LoadCompensationParams().slack_fraction * _cable_limits(robot)[0]


def _measured_forces(rec: Recorder) -> tuple[np.ndarray, np.ndarray]:
    """(t, f) of a run: the forces the loop measured (friction-compensated sensors, what the watch
    and the load compensation see) where every period has its state, else the plant's."""
    t, f = rec.array("t"), rec.array("f")
    states = rec.rows.get("state", [])
    if len(states) == len(t) and all(s is not None for s in states):
        f = np.array([s.f for s in states])
    return t, f


MODEL_REFERENCE_NOTE = ("sag reference: the elastic sag C_x w (4.5)-(4.6) at the run's unloaded forces (IK-only "
                        "leaves cables slack at this pose)")


def elastic_sag(robot, x, f, mass: float) -> float:
    """z [m] by which ``mass`` [kg] lowers the platform at x with the commanded lengths fixed and the
    cables at the forces f (m,): the z part of C_x w (4.5)-(4.6), w the payload's weight (the
    displacement the load compensation would cancel; nominal cable model (2.16)-(2.17))."""
    from cdpr_control.control.load_compensation import cable_stiffness_model, compliance, load_offset
    from cdpr_control.model.kinematics import inverse_kinematics

    ik = inverse_kinematics(robot, np.asarray(x, dtype=float))
    k_l = cable_stiffness_model(robot, ik, f, "nonlinear")
    return -float(load_offset(compliance(ik, f, k_l), mass, robot.gravity)[2])


def _rest_forces(rec) -> np.ndarray:
    """The cable forces (m,) [N], mean over the end of the unloaded rest (the sag's window)."""
    t = rec.array("t")
    return rec.array("f")[(t > PAYLOAD_REST - SAG_WINDOW) & (t <= PAYLOAD_REST)].mean(axis=0)


def ik_only_slack(robot, reference: Recorder) -> str | None:
    """Why IK-only control does not hold the empty platform at this pose with its cables tensed
    (None where it does), from the reference run's rest before the payload: a cable below the force
    watch's lower edge (f_min less its band, the watch would hold ik_lc there before any payload),
    or a window-mean force below the load compensation's slack share of f_min (no stiffness for
    (4.6)). IK-only commands lengths, not forces: its cables carry what the pre-tension set at home
    leaves at the pose (thesis 3.1.2, "the cable forces can only be controlled in limited manner by
    the initial pre-tension of the cables in the home position"), and x_d,LC, a pose offset, cannot
    tension a slack cable; the thesis evaluates the compensation near home only (4.1.3)."""
    from cdpr_tools.identify.load_steps import loop_params

    t, f = reference.array("t"), reference.array("f")
    if not len(t):
        return None
    f_min, f_max = _cable_limits(robot)
    rest = t <= PAYLOAD_REST
    lowest = f[rest].min(axis=0)
    edge = f_min - loop_params(REFERENCE, robot.file.stem).safety.force_band * (f_max - f_min)
    window = f[rest & (t > PAYLOAD_REST - SAG_WINDOW)].mean(axis=0)
    slack = window < _slack_force(robot)
    low = np.flatnonzero((lowest < edge) | slack)
    if not len(low):
        return None
    cables = ", ".join(f"{i + 1} ({lowest[i]:.1f} N)" for i in low)
    return (f"IK-only control does not hold this pose's cables tensed before any payload: cable(s) {cables} "
            f"at their lowest in the unloaded rest (force watch edge {edge.min():.1f} N); its forces are the home "
            "pre-tension's (thesis 3.1.2) and x_d,LC cannot tension a slack cable")


def _payload_result(spec: CaseSpec, robot, mass: float, base: dict, sag_reference: float | None,
                    note_ref: str) -> CaseResult:
    """One controller's run: a run that diverged fails as diverged, one the force watch held as held,
    with the reason in the note. sag_reference [mm] None: :func:`elastic_sag` at the run's own
    unloaded forces. The sag is the loaded run's true z at the end against that of its unloaded
    twin (the same run, plant and seed with no payload): what force control still moves the
    platform by over the dwell with no payload (its start-up convergence through the OSPC's
    integral part, up to 0.1 mm on the Mini at 0.7 s, docs/validation.md "Payload after session 17")
    is not the payload's sag; a twin that diverged or was held leaves the sag unmeasured (failed)."""
    rec, m_c, ok, held = _payload_run(spec, robot, spec.variant["controller"], mass)
    after = rec.array("t") >= PAYLOAD_REST + 1.0
    f = rec.array("f")
    if sag_reference is None:                 # payload_case: IK-only gives none at this pose
        sag_reference = 1e3 * elastic_sag(robot, spec.x, _rest_forces(rec), mass)
    # held by the force watch or by any other holding fault of the loop (the forward kinematics
    # not converging, a pose lag): what follows is the held command's, not the controller's
    usable = ok and held is None and rec.held is None
    twin, twin_failed = None, ""
    if usable:
        # the same run with no payload: what the platform does over the dwell whatever the payload
        # (the controller's start-up convergence, the OSPC's integral part) is not the payload's sag
        twin, _, ok_twin, held_twin = _payload_run(spec, robot, spec.variant["controller"], 0.0)
        if not ok_twin or held_twin is not None or twin.held is not None:
            twin_failed = f"the unloaded twin run {'diverged' if not ok_twin else 'was held'}: no sag measured"
    sag = 1e3 * _sag(rec, twin) if usable and not twin_failed else float("nan")
    accuracy = 1e3 * static_accuracy(rec, float(spec.x[2]))
    resolution = 1e3 * sag_resolution(1e-3 * accuracy, spec.plant)
    metrics = {**base, "estimate_error_percent": criteria.estimate_error_percent(m_c[after], mass) if usable
               else float("nan"), "sag_reference_mm": sag_reference, "sag_mm": sag,
               "sag_cut_percent": criteria.sag_cut_percent(sag_reference, sag),
               "static_accuracy_mm": accuracy, "sag_resolution_mm": resolution,
               "max_force_N": float(f.max()) if len(f) else float("nan"),
               "held_at_s": float("nan") if held is None else held[0]}
    if usable and not twin_failed:
        metrics.update(sag_diagnosis(robot, spec.x, rec, twin))
    slack = getattr(rec, "slack_cables", None)
    if slack is not None and len(slack) == len(after):
        # the load compensation's own diagnostic: cables slack under the payload (x_d,LC cannot tension them)
        metrics["slack_cables_after_step"] = float(slack[after].max()) if after.any() else float("nan")
    notes = ["" if ok else f"diverged at {rec.diverged_at:.3f} s", note_ref, twin_failed]
    unjudged = ()
    if abs(sag_reference) < resolution:
        # the cut in percent of a reference below the resolution measures the static accuracy, not
        # the compensation: judged instead on the residual, which must stay within the accuracy
        metrics["sag_residual_beyond_accuracy_mm"] = abs(sag) - accuracy
        unjudged = ("sag_cut_percent",)
        notes.append(f"{SAG_BELOW_RESOLUTION}: reference {sag_reference:.3g} mm below the resolution "
                     f"{resolution:.3g} mm (static accuracy {accuracy:.3g} mm with no payload), residual "
                     f"{sag:.3g} mm")
        within = criteria.BANDS["sag_residual_beyond_accuracy_mm"].holds(metrics["sag_residual_beyond_accuracy_mm"])
    else:
        within = criteria.SAG_CUT[spec.plant].holds(metrics["sag_cut_percent"])
    if usable and not within:
        notes.append(diagnosis_note(metrics))
    if getattr(rec, "lc_warning", None) and spec.variant.get("controller") == "ik_lc":
        notes.append(f"the load compensation warned: {rec.lc_warning}")
    held_text = rec.held or (None if held is None else f"held by the force watch at {held[0]:.3f} s ({held[1]})")
    return judge(spec, metrics, not ok, "; ".join(n for n in notes if n), held_text, unjudged)


SAG_BELOW_RESOLUTION = "sag below resolution"


# ---- (d) program --------------------------------------------------------------------------------

def border_program(robot, poses) -> str:
    """G-code from home to each of ``poses`` (border poses, positions) and back home after each,
    at the interpolator's speed limit: lines through home stay in a workspace star-shaped about it."""
    home = 1e3 * np.asarray(robot.home[:3])
    lines = ["G21 G90", "G1 F60000"]
    for x in poses:
        for p in (1e3 * np.asarray(x[:3]), home):
            lines.append("G1 X{:.1f} Y{:.1f} Z{:.1f}".format(*p))
    lines += ["G4 P0.5", "M30"]
    return "\n".join(lines) + "\n"


def shipped_limits(robot_name: str):
    """The interpolator's limits of the shipped configuration: the ``gcode_interpreter`` section of
    the robot's parameter file over the node's defaults (the graph gives the node that file), as the
    node builds them (``limits_from``)."""
    from cdpr_control.nodes.gcode_interpreter import limits_from, parameters

    robot = load_robot(robot_name)
    values = {p.name: p.default for p in parameters(robot)}
    values.update(file_section(robot_name, "gcode_interpreter"))
    return limits_from(values)


def program_case(spec: CaseSpec) -> CaseResult:
    """The border program under ``spec.variant["controller"]`` (force_control or ik_only), at the
    interpolator's limits of the shipped configuration (:func:`shipped_limits`): pose error (ground
    truth against the set-point) and the cable forces against the robot's limits from 0.1 s on (the
    start-up raises them to the planned f_min).

    ik_only is the reference (criteria.NOT_JUDGED): it commands lengths, its cables slacken on the
    way to the border, and its slack is reported, not judged. Its force watch is off, as for the
    payload family's IK-only reference: on, it held the Mini's every IK-only program within 0.5 s
    (a cable 3 N below f_min for 50 ms) and failed the case for the slack the family does not judge,
    while the IPAnema 3's watch band (5 % of 2900 N below f_min 100 N) never trips at 0 N. f_max
    and divergence are still judged, by the metrics and the recorder."""
    from cdpr_control.motion.gcode import parse_gcode
    from cdpr_control.motion.interpolation import Interpolator
    from cdpr_control.motion.program_check import check_program
    from cdpr_sim.closed_loop import program

    robot = load_robot(spec.robot)
    text = border_program(robot, spec.variant["poses"])
    parsed = parse_gcode(text, start_pose=robot.home)
    check_program(parsed, robot)                                   # GCodeError: the path leaves the workspace
    interp = Interpolator(parsed, shipped_limits(spec.robot), dt=DT)
    inner, x_d = program(interp), []

    def source(t):                                  # the set-point of each period, as given to the loop
        out = inner(t)
        x_d.append(out[0])
        return out

    params = control_loop_params(robot, mode=spec.variant["controller"])
    if spec.variant["controller"] == "ik_only":
        params = replace(params, safety=replace(params.safety, force_watch=False))
    rec = Recorder(robot)
    ok = recorded_run(robot, rec, source, interp.duration, params, config=sim_config(spec))
    t, x, f = rec.array("t"), rec.array("x"), rec.array("f")
    metrics = dict.fromkeys(("position_error_rms_mm", "position_error_max_mm", "force_below_f_min_N",
                             "force_above_f_max_N"), float("nan"))
    metrics["duration_s"] = float(interp.duration)
    if ok:
        x_d = np.array(x_d[:len(t)])                # period k's set-point, period k's outcome
        e = 1e3 * np.linalg.norm(x[:, :3] - x_d[:, :3], axis=1)
        settled = t >= 0.1
        below = np.broadcast_to(robot.cable.f_min, f[settled].shape) - f[settled]
        k, c = np.unravel_index(np.argmax(below), below.shape)
        metrics.update(position_error_rms_mm=float(np.sqrt(np.mean(e ** 2))), position_error_max_mm=float(e.max()),
                       force_below_f_min_N=float(below[k, c]),
                       force_above_f_max_N=float((f[settled] - robot.cable.f_max).max()))
        # where the lowest force was: the worst case's where within the program
        note = (f"lowest cable force {f[settled][k, c]:.4g} N (cable {c + 1}) at {t[settled][k]:.3f} s, platform at "
                f"[{', '.join(f'{v:.3f}' for v in x[settled][k, :3])}]")
    return judge(spec, metrics, not ok, note if ok else f"diverged at {rec.diverged_at:.3f} s", rec.held)


RUNNERS = {"contact": contact_case, "guiding": guiding_case, "payload": payload_case, "program": program_case}
FAMILIES = tuple(RUNNERS)


def run_case(spec: CaseSpec) -> list[CaseResult]:
    """Run a case (the payload family: one result per controller); an exception of the runner
    (not of the controller) is the case's error, with its reason."""
    try:
        out = RUNNERS[spec.family](spec)
    except Exception as exc:                       # noqa: BLE001 - reported per case, the sweep goes on
        last = traceback.extract_tb(exc.__traceback__)[-1]
        where = f"{last.filename.rsplit('/', 1)[-1]}:{last.lineno}"
        return [CaseResult(spec, {}, {}, "error", f"{type(exc).__name__}: {exc} ({where})")]
    return out if isinstance(out, list) else [out]
