"""The sweep's case runners, one per family, each in process: the robot's shipped parameter file in
:class:`cdpr_control.control.loop.ControlLoop` against the simulator (:func:`cdpr_sim.closed_loop.run`).

* contact (a): hybrid position/force control (section 5.1) pressing on a floor below the tool;
* guiding (b): hand guiding (section 5.2) at rest, pushed, and released for the eigenfrequency (5.12);
* payload (c): a payload step (section 4.1.3) under force control and under IK-only with load compensation;
* program (d): a G-code program through the workspace's border region under force control and IK-only.

Every run watches its cable forces: beyond DIVERGENCE_FACTOR * f_max, or non-finite, it is stopped
and the case fails as diverged. :func:`run_case` returns a case's :class:`CaseResult` (one per
controller for payloads); it never raises for what the controller did (an exception of the runner
itself is reported as the case's error).

The runners are the sweep's own: the library has no in-process runner for contact at an arbitrary
pose, the hand-guiding one (:func:`cdpr_tools.admittance_figure.guiding_run`) guides only from home
with part of the parameter file, and the payload one (:mod:`cdpr_tools.identify.load_steps`) takes
no orientation and has no divergence stop.
"""
from __future__ import annotations

import traceback
from dataclasses import dataclass, field

import numpy as np

from cdpr_control.control.params import control_loop_params, load_params_file
from cdpr_control.control.hybrid_force_control import HPFCParams, HybridForceControl
from cdpr_control.model.kinematics import rotation_matrix
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import HandGuiding, hold, run
from cdpr_sim.contacts import ContactMaterial, Plane, default_tool
from cdpr_sim.simulator import SimConfig

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
PAYLOAD_FRACTIONS = (0.25, 0.5, 1.0)               # of the pose's static capacity
# s: tared empty, the step (cosine), after it; the dwell lets the load compensation's output filter
# (T_output 1 s) and the OSPC's integral part (T_i / K_p about 2.6 s) reach the static sag
PAYLOAD_REST, PAYLOAD_RAMP, PAYLOAD_DWELL = 0.7, 0.3, 4.0
PAYLOAD_CONTROLLERS = ("force_control", "ik_lc")   # identify.load_steps.CONFIGS: the shipped graph; IK-only + (4.6)
SAG_WINDOW = 0.3                                   # s: mean z error at the end of rest and dwell
PUSH_DIRECTIONS = ((1, 0, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1), (1, 1, -1), (-1, 1, 0))
PUSH_SHARE = 0.65                                  # of w_max (the Mini: 13 N, the push of issue 25)
REST_TIME, PUSH_START, PUSH_RELEASE, PUSH_END = 0.5, 0.2, 1.2, 2.0   # s
# table 5.3, row 3 (c, d, m of x; 1.0 Hz), and the zones that keep the oscillation inside the rest sphere
EIGEN_ZONE = {"zones.rest.radius": 0.03, "zones.free.box": [0.05] * 6}
EIGEN_CDM = (395.4, 5.0, 10.0)
EIGEN_PUSH, EIGEN_WINDOW = 0.2, 1.0                # s: push length, fitted window after the release


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


@dataclass
class CaseResult:
    spec: CaseSpec
    metrics: dict                # name -> value (NaN: not computed)
    checks: dict                 # metric name -> within its band
    status: str                  # passed, failed, diverged, refused (the configuration is refused there), error
    note: str = ""
    wall_s: float = 0.0          # wall-clock time of the case's runs
    cpu_s: float = 0.0           # CPU time of its process over them (what the sweep costs on an idle machine)

    @property
    def passed(self) -> bool:
        return self.status == "passed"


class Recorder:
    """A ``before_step`` hook of :func:`cdpr_sim.closed_loop.run` recording the ground truth and
    the loop's state of each period, and stopping the run when it diverges."""

    def __init__(self, robot, hooks=()):
        self.f_stop = DIVERGENCE_FACTOR * np.asarray(robot.cable.f_max, dtype=float)
        self.hooks = list(hooks)
        self.rows = {"t": [], "x": [], "f": [], "w_contact": [], "state": []}
        self.diverged_at: float | None = None

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


def judge(spec: CaseSpec, metrics: dict, diverged: bool, note: str = "") -> CaseResult:
    metrics = {**metrics, "diverged": float(diverged)}
    checks = {}
    for name, value in metrics.items():
        band = criteria.band_for(name, spec.plant)
        if band is not None:
            checks[name] = band.holds(value)
    status = "diverged" if diverged else "passed" if all(checks.values()) else "failed"
    return CaseResult(spec, metrics, checks, status, note)


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

    def settle_then_press(k_, loop, sim):
        if k_ == n_settle:                     # the floor in place, then M103
            sim.place_obstacle(0, (x[0], x[1], lowest - gap))
            loop.set_parameter("hybrid_force_controller", "enabled", True)
        if loop.failure is not None:
            held.setdefault("reason", loop.failure)
    rec.hooks += [settle_then_press, _settled_watch(rec, F_d)]
    params = control_loop_params(robot, hpfc=hpfc, hpfc_enabled=False)
    v_approach = HybridForceControl(robot, DT, hpfc).approach_speed(F_d)      # (below v_max on stiff floors)
    duration = SETTLE_TIME + params.transfer_time + gap / v_approach + CONTACT_TIME
    ok = recorded_run(robot, rec, source, duration, params, x0=x, config=sim_config(spec, obstacles=(floor,)))
    t, F, f = rec.array("t"), rec.array("w_contact")[:, 2], rec.array("f")
    states = np.array([s.hpfc.state for s in rec.rows["state"]])
    touched = np.flatnonzero(F > 0.0)
    metrics = dict.fromkeys(("overshoot_percent", "settling_s", "steady_error_percent", "slack_s"), float("nan"))
    metrics["time_in_B_s"] = float(np.count_nonzero(states == "B") * DT)
    metrics["impact_s"] = float(t[touched[0]]) if len(touched) else float("nan")
    if len(touched) and ok:
        i = touched[0]
        metrics.update(overshoot_percent=criteria.overshoot_percent(F[i:], F_d),
                       settling_s=criteria.settling_time(t[i:], F[i:], F_d),
                       steady_error_percent=criteria.steady_error_percent(F[i:], F_d, int(STEADY_WINDOW / DT)),
                       slack_s=criteria.slack_time(f[i:], robot.cable.f_min, DT))
    note = "" if len(touched) else "never touched the floor"
    if "reason" in held:
        note = f"held by the force watch: {held['reason']}" + (f"; {note}" if note else "")
    return judge(spec, metrics, not ok, note or (f"diverged at {rec.diverged_at:.3f} s" if not ok else ""))


def _settled_watch(rec: Recorder, F_d: float):
    """A hook ending the run (:class:`Done`) once the true contact force has been within the 2 %
    band for SETTLED_HOLD s and for STEADY_WINDOW s at least after the impact."""
    n_hold, n_steady = int(SETTLED_HOLD / DT), int(STEADY_WINDOW / DT)
    state = {"impact": None, "inside": 0}

    def watch(k, loop, sim):
        w = rec.rows["w_contact"]
        if not w:
            return
        F = w[-1][2]
        if state["impact"] is None and F > 0.0:
            state["impact"] = len(w) - 1
        if state["impact"] is not None:
            state["inside"] = state["inside"] + 1 if abs(F - F_d) <= 0.02 * F_d else 0
            if state["inside"] >= max(n_hold, n_steady):
                raise Done
    return watch


# ---- (b) hand guiding ---------------------------------------------------------------------------

def _settings(spec: CaseSpec, robot, overrides: dict):
    """(params, zones, robot with the known payload) of the shipped admittance_controller section
    with ``overrides``, the zones' origin at the pose; ValueError: refused at this pose."""
    from cdpr_control.control.admittance import settings_from

    values = {**file_section(spec.robot, "admittance_controller"), **overrides,
              "zones.origin": list(np.asarray(spec.x, dtype=float) - robot.home)}
    values.pop("hand_guiding", None)
    return settings_from(values, robot)


def _guiding(spec: CaseSpec, robot, settings, segments, duration: float):
    """Hand guiding at the pose with ``settings`` (:func:`_settings`), enabled at t = 0, the
    simulated hand pushing ``segments`` -> (recorder, source, ok)."""
    from cdpr_control.control.admittance import AdmittanceController
    from cdpr_sim.hand import Hand

    params, zones, loaded = settings
    x = np.asarray(spec.x, dtype=float)
    controller = AdmittanceController(loaded, file_section(spec.robot, "/**").get("control_period", DT), params, zones)
    controller.enable()
    source, hand = HandGuiding(controller, x), Hand(list(segments))
    rec = Recorder(robot, [lambda k, loop, sim: hand.apply(sim)])
    ok = recorded_run(robot, rec, source, duration, control_loop_params(robot), x0=x, config=sim_config(spec))
    return rec, source, ok


def guiding_case(spec: CaseSpec) -> CaseResult:
    """At rest with nobody pushing (REST_TIME), then a push of PUSH_SHARE w_max in the variant's
    direction held until PUSH_RELEASE and released; then the eigenfrequency: the rest zone of
    table 5.3 (row 3), a short push along x, released, the ground truth's oscillation fitted."""
    from cdpr_control.control.admittance import damped_eigenfrequency
    from cdpr_control.control.admittance_zones import per_axis
    from cdpr_sim.hand import Segment

    robot = load_robot(spec.robot)
    try:
        settings = _settings(spec, robot, {})
    except ValueError as exc:
        return CaseResult(spec, {}, {}, "refused", f"hand guiding refused at this pose: {exc}")
    w_max = per_axis(settings[0].user.w_max, "w_max")
    rec, source, ok = _guiding(spec, robot, settings, [], REST_TIME)
    metrics = {"rest_motion_mm": criteria.rest_motion_mm(rec.array("x")) if ok else float("nan"),
               "rest_wrench_percent": criteria.wrench_share_percent([o.w_user for o in source.outputs], w_max)}
    notes = [] if ok else [f"diverged at rest at {rec.diverged_at:.3f} s"]
    direction = np.asarray(spec.variant["direction"], dtype=float)
    push = np.r_[PUSH_SHARE * w_max[0] * direction / np.linalg.norm(direction), np.zeros(3)]
    rec2, _, ok2 = _guiding(spec, robot, settings, [Segment(PUSH_START, tuple(push), "step"),
                                                    Segment(PUSH_RELEASE, release=True)], PUSH_END)
    f = rec2.array("f")
    settled = rec2.array("t") >= 0.1                      # the start-up raises the cables to the planned f_min
    metrics["push_force_margin_N"] = float((f[settled] - robot.cable.f_min).min()) if ok2 and settled.any() else float("nan")
    metrics["push_min_force_N"] = float(f[settled].min()) if settled.any() else float("nan")
    if not ok2:
        notes.append(f"diverged under the push at {rec2.diverged_at:.3f} s")
    c, d, m = EIGEN_CDM
    overrides = {**EIGEN_ZONE, "zones.rest.c": [c, 1000.0, 1000.0, 20.0, 20.0, 20.0],
                 "zones.rest.d": [d, 40.0, 40.0, 0.5, 0.5, 0.5], "zones.rest.m": [m, 2.0, 2.0, 0.01, 0.01, 0.01]}
    release = 0.05 + EIGEN_PUSH
    ok3 = True
    try:
        eigen = _settings(spec, robot, overrides)
        push_x = per_axis(eigen[0].user.dead_band, "dead_band")[0] + 1.5   # 1.5 N through the dead band (the Mini test's 2 N)
        rec3, _, ok3 = _guiding(spec, robot, eigen, [Segment(0.05, (push_x, 0, 0, 0, 0, 0), "rectangle", EIGEN_PUSH)],
                                release + 0.05 + EIGEN_WINDOW)
        t3, x3 = rec3.array("t"), rec3.array("x")
        sel = t3 > release + 0.05
        f_exp = criteria.fitted_frequency(t3[sel], x3[sel, 0]) if ok3 and sel.sum() > 10 else float("nan")
        f_theo = damped_eigenfrequency(c, d, m)
        metrics["eigenfrequency_Hz"] = f_exp
        metrics["eigenfrequency_error_percent"] = 100.0 * (f_exp - f_theo) / f_theo
        if not ok3:
            notes.append(f"diverged in the eigenfrequency run at {rec3.diverged_at:.3f} s")
    except ValueError as exc:
        notes.append(f"eigenfrequency zones refused: {exc}")
        metrics["eigenfrequency_error_percent"] = float("nan")
    return judge(spec, metrics, not (ok and ok2 and ok3), "; ".join(notes))


# ---- (c) payload --------------------------------------------------------------------------------

def _payload_run(spec: CaseSpec, robot, config: str, mass: float):
    """A payload step at the pose: REST tared empty, the step over PAYLOAD_RAMP (cosine, as a load
    put down by hand: an instantaneous step rings the lightly damped vertical mode), PAYLOAD_DWELL
    after it -> (recorder, m_c (N,), ok)."""
    from cdpr_control.control.load_compensation import LoadCompensationParams, LoadCompensationStage
    from cdpr_tools.identify.load_steps import CONFIGS, loop_params

    x = np.asarray(spec.x, dtype=float)
    lc_values = {k: v for k, v in file_section(spec.robot, "load_compensation").items()
                 if k in LoadCompensationParams.__dataclass_fields__}
    params = LoadCompensationParams(**{**lc_values, "enabled": CONFIGS[config][2]})
    stage = LoadCompensationStage(robot, DT, params, feed_force_setpoint=CONFIGS[config][3])
    n_rest, n_ramp = int(round(PAYLOAD_REST / DT)), int(round(PAYLOAD_RAMP / DT))
    m_c = []

    def put_down(k, loop, sim):
        if k > 0:
            m_c.append(stage.compensation.m_c)
        i = k - n_rest
        if 0 <= i < n_ramp + 1:
            sim.set_payload(mass * (0.5 * (1.0 - np.cos(np.pi * min(i + 1, n_ramp) / n_ramp))))

    rec = Recorder(robot, [put_down])
    ok = recorded_run(robot, rec, hold(x), PAYLOAD_REST + PAYLOAD_RAMP + PAYLOAD_DWELL, loop_params(config, spec.robot),
                      x0=x, offset_stages={"load_compensation": stage}, config=sim_config(spec))
    return rec, np.array(m_c, dtype=float), ok


def _sag(rec) -> float:
    """Static z error [m] at the end of the dwell, from the unloaded one at the end of the rest."""
    t, z = rec.array("t"), rec.array("x")[:, 2]
    n = int(SAG_WINDOW / DT)
    rest = (t > PAYLOAD_REST - SAG_WINDOW) & (t <= PAYLOAD_REST)
    return float(z[-n:].mean() - z[rest].mean())


def payload_case(spec: CaseSpec) -> list[CaseResult]:
    """Payload step of the variant's fraction of the pose's static capacity
    (:func:`cdpr_control.motion.program_check.payload_capacity`) under each of PAYLOAD_CONTROLLERS
    (force_control: CFC + OSPC with the identified payload in the force set-point, the shipped
    graph; ik_lc: IK-only with load compensation), one result each, and under IK-only without
    compensation (the reference sag). Estimate error from 1 s after the step began; sag cut
    against the reference."""
    from dataclasses import replace

    from cdpr_control.motion.program_check import payload_capacity

    robot = load_robot(spec.robot)
    capacity = payload_capacity(robot, spec.x)
    mass = spec.variant["fraction"] * capacity
    specs = [replace(spec, variant={**spec.variant, "controller": c}) for c in PAYLOAD_CONTROLLERS]
    base = {"capacity_kg": capacity, "payload_kg": mass}
    if mass < 0.1 * robot.platform.mass:
        return [CaseResult(s, dict(base), {}, "refused", f"static capacity {capacity:.3g} kg at this pose: no step to make")
                for s in specs]
    reference, _, ok_ref = _payload_run(spec, robot, "ik", mass)
    sag_reference = 1e3 * _sag(reference) if ok_ref else float("nan")
    return [_payload_result(s, robot, mass, base, sag_reference, reference if not ok_ref else None) for s in specs]


def _payload_result(spec: CaseSpec, robot, mass: float, base: dict, sag_reference: float, failed_reference) -> CaseResult:
    rec, m_c, ok = _payload_run(spec, robot, spec.variant["controller"], mass)
    after = rec.array("t") >= PAYLOAD_REST + 1.0
    f = rec.array("f")
    sag = 1e3 * _sag(rec) if ok else float("nan")
    metrics = {**base, "estimate_error_percent": criteria.estimate_error_percent(m_c[after], mass) if ok else float("nan"),
               "sag_reference_mm": sag_reference, "sag_mm": sag,
               "sag_cut_percent": criteria.sag_cut_percent(sag_reference, sag),
               "max_force_N": float(f.max()) if len(f) else float("nan")}
    note = "" if ok else f"diverged at {rec.diverged_at:.3f} s"
    if failed_reference is not None:
        note += f"; the IK-only reference diverged at {failed_reference.diverged_at:.3f} s"
    return judge(spec, metrics, not ok, note.strip("; "))


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


def program_case(spec: CaseSpec) -> CaseResult:
    """The border program under ``spec.variant["controller"]`` (force_control or ik_only): pose
    error (ground truth against the set-point) and the cable forces against the robot's limits
    from 0.1 s on (the start-up raises them to the planned f_min)."""
    from cdpr_control.motion.gcode import parse_gcode
    from cdpr_control.motion.interpolation import Interpolator
    from cdpr_control.motion.program_check import check_program
    from cdpr_sim.closed_loop import program

    robot = load_robot(spec.robot)
    text = border_program(robot, spec.variant["poses"])
    parsed = parse_gcode(text, start_pose=robot.home)
    check_program(parsed, robot)                                   # GCodeError: the path leaves the workspace
    interp = Interpolator(parsed, dt=DT)
    inner, x_d = program(interp), []

    def source(t):                                  # the set-point of each period, as given to the loop
        out = inner(t)
        x_d.append(out[0])
        return out

    rec = Recorder(robot)
    ok = recorded_run(robot, rec, source, interp.duration,
                      control_loop_params(robot, mode=spec.variant["controller"]), config=sim_config(spec))
    t, x, f = rec.array("t"), rec.array("x"), rec.array("f")
    metrics = dict.fromkeys(("position_error_rms_mm", "position_error_max_mm", "force_below_f_min_N",
                             "force_above_f_max_N"), float("nan"))
    metrics["duration_s"] = float(interp.duration)
    if ok:
        x_d = np.array(x_d[:len(t)])                # period k's set-point, period k's outcome
        e = 1e3 * np.linalg.norm(x[:, :3] - x_d[:, :3], axis=1)
        settled = t >= 0.1
        metrics.update(position_error_rms_mm=float(np.sqrt(np.mean(e ** 2))), position_error_max_mm=float(e.max()),
                       force_below_f_min_N=float((robot.cable.f_min - f[settled]).max()),
                       force_above_f_max_N=float((f[settled] - robot.cable.f_max).max()))
    return judge(spec, metrics, not ok, "" if ok else f"diverged at {rec.diverged_at:.3f} s")


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
