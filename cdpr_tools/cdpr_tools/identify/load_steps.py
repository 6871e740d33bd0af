"""Payload experiments of thesis section 4.1.3 in the simulator (Fig. 4.6, 4.7), in process.

* :func:`payload_steps`: payloads added in steps of ``step_mass`` at standstill, then removed
  again (16 x 8 kg at r = [-1, -1, 0.5] m on the IPAnema 3 in the thesis), through the simulator's
  ``set_payload`` (what ``/sim/set_payload`` calls in the graph).
* :func:`payload_program`: a program run with a payload carried from the start (Fig. 4.7).

Both close the control loop of :mod:`cdpr_sim.closed_loop` with the load compensation as an offset
stage, in one of the controller configurations of :data:`CONFIGS`:

- ``ik``: IK-only reference control (section 2.3.2): the cable force controller and the OSPC off;
- ``ik_lc``: IK-only + load compensation (4.6), as in the thesis' experiment;
- ``ospc``: OSPC on the elastic forward kinematics (3.16), cable force control off;
- ``ospc_lc``: both;
- ``force_control``: the thesis' force control (CFC + OSPC, Fig. 3.4), the default graph, with the
  identified payload in the force distribution's model wrench (``payload_input``);
- ``force_control_lc``: force control + load compensation;
- ``force_control_without_payload``: force control, the identified payload not used at all.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.params import control_loop_params
from cdpr_control.control.load_compensation import LoadCompensationParams, LoadCompensationStage
from cdpr_control.model.robot import load_robot

DIVERGENCE_FACTOR = 1.5   # a cable force beyond this times f_max: the run diverged (as cdpr validate)
CONFIGS = {
    "ik": (False, False, False, False), "ik_lc": (False, False, True, False), "ospc": (False, True, False, False),
    "ospc_lc": (False, True, True, False), "force_control": (True, True, False, True),
    "force_control_lc": (True, True, True, True), "force_control_without_payload": (True, True, False, False),
}   # name: (cable force control, OSPC, load compensation x_d,LC, identified payload into the force set-point)


@dataclass
class PayloadRun:
    """One run: time series (N,) per control period and the configuration."""

    config: str
    t: np.ndarray            # s
    payload: np.ndarray      # kg, true payload on the platform
    m_c: np.ndarray          # kg, estimated payload (m̂_p - m_p)
    guarded: np.ndarray      # (4.4) held its estimate
    x_d: np.ndarray          # (N, 6) set-point
    x: np.ndarray            # (N, 6) true pose
    x_lc: np.ndarray         # (N, 6) x_d,LC
    theta_d: np.ndarray      # (N, m) drive command
    f: np.ndarray            # (N, m) true cable forces [N]
    held_at: float | None = None   # s, when the force watch held the robot (control.safety.ForceWatch)
    hold_reason: str = ""          # its reason, as on /diagnostics

    def max_force(self) -> float:
        """Largest true cable force of the run [N] (NaN when a force was not finite)."""
        return float(np.max(self.f)) if np.all(np.isfinite(self.f)) else float("nan")

    def diverged(self, robot) -> bool:
        """A cable force beyond DIVERGENCE_FACTOR f_max, or not finite (the validation sweep's criterion)."""
        return not self.max_force() <= DIVERGENCE_FACTOR * float(np.max(robot.cable.f_max))


def loop_params(config: str, robot="ipanema3_mini") -> ControlLoopParams:
    """The robot's parameter file (as the node graph runs it) with the configuration's controllers."""
    cfc, ospc, _, _ = CONFIGS[config]
    return control_loop_params(robot, mode="force_control", cfc_enabled=cfc, ospc_enabled=ospc)


def _run(robot, setpoints, duration, config, x0, payload_at, lc_params=None, payload0=0.0, plant="mismatched",
         model=None):
    """Closed loop with the load compensation stage; payload_at(k) -> mass to set before step k or None;
    ``plant``: the simulator's (cdpr_sim.plant: mismatched by default, or nominal)."""
    from cdpr_sim.closed_loop import run
    from cdpr_sim.simulator import SimConfig

    lc_enabled = CONFIGS[config][2]
    # the platform starts at rest and empty: the estimate is tared there (the force sensors' offsets)
    params = lc_params or LoadCompensationParams(tare_at_start=True, tare_payload=payload0)
    params = LoadCompensationParams(**{**params.__dict__, "enabled": lc_enabled})
    # with cable force control the identified payload also feeds the force distribution's model
    # wrench, as the parameter files set it (force_distribution.payload_input)
    stage = LoadCompensationStage(robot if model is None else model, 1e-3, params, feed_force_setpoint=CONFIGS[config][3])
    lc = stage.compensation
    log = {"payload": [], "m_c": [], "guarded": []}
    current = [payload0]
    hold = {}                                  # the force watch's first hold: t, reason

    def before_step(k, loop, sim):
        mass = payload_at(k)
        if mass is not None and mass != current[0]:
            sim.set_payload(mass)
            current[0] = mass

    def record():
        log["payload"].append(current[0])
        log["m_c"].append(lc.m_c)
        log["guarded"].append(lc.guarded)

    def step_hook(k, loop, sim):
        if k > 0:
            record()                      # the state the loop computed in period k - 1
            if loop.failure is not None and not hold:
                hold.update(t=float(sim.output.t), reason=loop.failure)
        before_step(k, loop, sim)

    r = run(robot, setpoints, duration, loop_params(config, robot), x0=x0, payload=payload0, before_step=step_hook,
            offset_stages={"load_compensation": stage}, config=SimConfig(plant=plant))
    record()
    return PayloadRun(config, r.t, np.array(log["payload"]), np.array(log["m_c"]), np.array(log["guarded"]),
                      r.x_d, r.x, r.offsets["load_compensation"], r.theta_d, r.f, hold.get("t"), hold.get("reason", ""))


def step_schedule(step_mass: float, steps: int, down: bool = True) -> np.ndarray:
    """Payload [kg] per dwell interval: 0, then up in ``steps`` steps and (``down``) down again to 0."""
    up = step_mass * np.arange(1, steps + 1)
    return np.r_[0.0, up, up[-2::-1], 0.0] if down else np.r_[0.0, up]


def payload_steps(robot="ipanema3", config: str = "ik_lc", position=(-1.0, -1.0, 0.5), step_mass: float = 8.0,
                  steps: int = 16, dwell: float = 1.5, rest: float = 0.5, ramp: float = 0.3,
                  lc_params: LoadCompensationParams | None = None, plant: str = "mismatched",
                  down: bool = True, model=None) -> PayloadRun:
    """Payload steps at standstill (section 4.1.3, Fig. 4.6): ``rest`` s unloaded, then a step of
    ``step_mass`` every ``dwell`` s up to steps * step_mass and back to zero.

    ``down`` False: only the way up. ``model``: the load compensation's robot model (default
    ``robot``; the simulated plant is always built from ``robot``). Each step is applied over ``ramp`` s (cosine), as a plate put down by hand: an instantaneous
    step would excite the lightly damped vertical mode of the simulated platform (about 1 % of
    critical damping under load) for many seconds, which the hand-placed plates of the thesis did not.
    """
    robot = load_robot(robot) if isinstance(robot, str) else robot
    from cdpr_sim.closed_loop import hold

    x = robot.home.copy()
    x[:3] = position
    masses = step_schedule(step_mass, steps, down)
    n_rest, n_dwell, n_ramp = (int(round(v / 1e-3)) for v in (rest, dwell, ramp))

    def payload_at(k):
        if k < n_rest:
            return float(masses[0])
        j, i = divmod(k - n_rest, n_dwell)
        j = min(j + 1, len(masses) - 1)
        s = 1.0 if i >= n_ramp else 0.5 * (1.0 - np.cos(np.pi * (i + 1) / n_ramp))
        return float(masses[j - 1] + s * (masses[j] - masses[j - 1]))

    duration = rest + dwell * (len(masses) - 1)
    return _run(robot, hold(x), duration, config, x, payload_at, lc_params, plant=plant, model=model)


def step_summary(run: PayloadRun, dwell: float, rest: float, window: float = 0.3, settle: float = 1.0) -> dict:
    """Per step: the true payload, the mean z error and estimate over the last ``window`` s of each
    dwell, the estimate's mean over the ``window`` s before ``settle`` s after the step's start, and its
    worst error from ``settle`` s after the step to the next."""
    n_rest, n_dwell, n_win, n_settle = (int(round(v / 1e-3)) for v in (rest, dwell, window, settle))
    rows = []
    for j, start in enumerate(range(n_rest, len(run.t) - n_dwell + 1, n_dwell)):
        end = start + n_dwell
        payload = float(run.payload[end - 1])
        z = 1e3 * (run.x[end - n_win:end, 2] - run.x_d[end - n_win:end, 2])
        est = run.m_c[start + n_settle:end]
        rows.append({"payload_kg": payload, "z_error_mm": float(z.mean()),
                     "estimate_kg": float(run.m_c[end - n_win:end].mean()),
                     "estimate_1s_kg": float(run.m_c[start + n_settle - n_win:start + n_settle].mean()),
                     "estimate_error_kg": float(np.abs(est - payload).max()),
                     "x_lc_z_mm": float(1e3 * run.x_lc[end - n_win:end, 2].mean())})
    lo = max(n_rest - n_win, 0)
    unloaded = 1e3 * (run.x[lo:n_rest, 2] - run.x_d[lo:n_rest, 2]).mean()
    return {"config": run.config, "unloaded_z_error_mm": float(unloaded), "steps": rows}


def sag_per_kg(summary: dict) -> float:
    """Slope of the z error over the payload on the way up [mm/kg] (least squares through the
    unloaded error), the figure the thesis gives as 0.37 mm/kg."""
    rows = [r for r in summary["steps"]]
    peak = int(np.argmax([r["payload_kg"] for r in rows]))
    m = np.array([r["payload_kg"] for r in rows[:peak + 1]])
    dz = np.array([r["z_error_mm"] for r in rows[:peak + 1]]) - summary["unloaded_z_error_mm"]
    return float(-(m @ dz) / (m @ m))


def payload_program(robot="ipanema3", config: str = "ik_lc", payload: float = 40.0,
                    program: str = "payload_moves_ipanema3", lc_params: LoadCompensationParams | None = None,
                    tail: float = 0.5, ramp: float = 0.3, plant: str = "mismatched", rest: float = 0.5,
                    model=None) -> PayloadRun:
    """A program run with ``payload`` kg put on the platform (cosine over ``ramp`` s) ``rest`` s after
    its start (Fig. 4.7; the estimate is tared empty before); ``program`` a shipped program name or
    a .gcode file; ``model`` the load compensation's robot model (as :func:`payload_steps`)."""
    from cdpr_control import programs
    from cdpr_control.motion.gcode import parse_gcode
    from cdpr_control.motion.interpolation import Interpolator
    from cdpr_sim.closed_loop import program as program_source

    robot = load_robot(robot) if isinstance(robot, str) else robot
    text = Path(program).read_text() if program.endswith(".gcode") else programs.read(program)
    interp = Interpolator(parse_gcode(text, start_pose=robot.home), dt=1e-3)
    n_ramp, n_rest = max(int(round(ramp / 1e-3)), 1), int(round(rest / 1e-3))

    def payload_at(k):
        k -= n_rest
        return payload * (0.0 if k < 0 else 1.0 if k >= n_ramp else 0.5 * (1.0 - np.cos(np.pi * (k + 1) / n_ramp)))

    return _run(robot, program_source(interp), interp.duration + tail, config, robot.home, payload_at, lc_params,
                plant=plant, model=model)


def plot_steps(runs: dict, path, title: str = "") -> Path:
    """z error, estimated payload and x_d,LC over time (Fig. 4.6), one line per configuration."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(3, 1, figsize=(7.0, 6.0), sharex=True)
    for name, run in runs.items():
        ax[0].plot(run.t, 1e3 * (run.x[:, 2] - run.x_d[:, 2]), lw=0.7, label=name)
        if CONFIGS[name][2]:
            ax[1].plot(run.t, run.m_c, lw=0.7, label=f"estimate ({name})")
            ax[2].plot(run.t, 1e3 * run.x_lc[:, 2], lw=0.7, label=name)
    first = next(iter(runs.values()))
    ax[1].plot(first.t, first.payload, "k--", lw=0.8, label="true payload")
    ax[0].set_ylabel("z error [mm]")
    ax[1].set_ylabel("payload m_c [kg]")
    ax[2].set_ylabel("x_d,LC z [mm]")
    ax[2].set_xlabel("t [s]")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7, loc="upper right")
    if title:
        ax[0].set_title(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def estimate_settle_percent(summary: dict, step_mass: float) -> float:
    """Worst error of the estimate 1 s after a step (:func:`step_summary`'s estimate_1s_kg) in % of
    the payload (of the step for the step back to zero): the issue's 3 % criterion."""
    return float(max(100.0 * abs(r["estimate_1s_kg"] - r["payload_kg"]) / max(r["payload_kg"], step_mass)
                     for r in summary["steps"]))


def sag_cut_percent(reference: dict, compensated: dict) -> list:
    """Per loaded step, the share of the static sag of ``reference`` (IK-only) that ``compensated``
    removes [%] (sags from the unloaded error of each run)."""
    cuts = []
    for a, b in zip(reference["steps"], compensated["steps"]):
        if a["payload_kg"] > 0.0:
            sag = a["z_error_mm"] - reference["unloaded_z_error_mm"]
            rest = b["z_error_mm"] - compensated["unloaded_z_error_mm"]
            cuts.append(float(100.0 * (1.0 - abs(rest) / abs(sag))))
    return cuts


def run_experiment(outdir, robot="ipanema3", configs=("ik", "ik_lc", "ospc", "force_control", "force_control_lc"),
                   position=(-1.0, -1.0, 0.5), step_mass: float = 8.0, steps: int = 16, dwell: float = 1.5,
                   rest: float = 0.5, progress=print, plant: str = "mismatched", model=None,
                   lc_params: LoadCompensationParams | None = None) -> dict:
    """The standstill experiment for each configuration: plot, JSON summary; returns the summary
    (per configuration; with ``ik`` also the sag cut of each other configuration against it).
    model: the load compensation's robot model (a robot file name or path, or a Robot; e.g. one with
    the identified cable parameters); None: ``robot``, whose nominal parameters the plant is built from."""
    model = load_robot(model) if isinstance(model, (str, Path)) else model
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    runs, summary = {}, {}
    for config in configs:
        progress(f"payload steps, {config} ...")
        runs[config] = payload_steps(robot, config, position, step_mass=step_mass, steps=steps, dwell=dwell, rest=rest,
                                     plant=plant, model=model, lc_params=lc_params)
        s = step_summary(runs[config], dwell, rest)
        s["plant"] = plant
        s["model"] = "robot" if model is None else model.name
        s["sag_mm_per_kg"] = sag_per_kg(s)
        s["max_abs_z_error_mm"] = float(max(abs(r["z_error_mm"]) for r in s["steps"]))
        s["estimate_settle_percent"] = estimate_settle_percent(s, step_mass)
        s.update(run_outcome(runs[config], robot))
        if "ik" in summary and config != "ik":
            s["sag_cut_percent"] = sag_cut_percent(summary["ik"], s)
        summary[config] = s
        progress(f"  sag {s['sag_mm_per_kg']:.3f} mm/kg, worst static z error {s['max_abs_z_error_mm']:.1f} mm, "
                 f"estimate 1 s after a step within {s['estimate_settle_percent']:.1f} %"
                 + (f", sag cut {min(s['sag_cut_percent']):.1f} % (worst) / {s['sag_cut_percent'][steps - 1]:.1f} % "
                    f"at {steps * step_mass:g} kg" if "sag_cut_percent" in s else ""))
        if not s["ok"]:
            progress(f"  NOT OK: {s['outcome']}")
    plot_steps(runs, outdir / "load_compensation_steps.png",
               f"{steps} x {step_mass:g} kg at standstill, simulated {robot if isinstance(robot, str) else robot.name}, {plant} plant")
    (outdir / "load_compensation_steps.json").write_text(json.dumps(summary, indent=1))
    return summary


def run_outcome(run: PayloadRun, robot) -> dict:
    """Whether a run is usable: ``ok`` False when it diverged (a cable beyond DIVERGENCE_FACTOR f_max)
    or the force watch held the robot (its figures are then those of a held robot, not of the
    controller); ``outcome`` says which, when and why; the largest cable force."""
    robot = load_robot(robot) if isinstance(robot, (str, Path)) else robot
    f_max = float(np.max(robot.cable.f_max))
    parts = []
    if run.diverged(robot):
        parts.append(f"diverged: largest cable force {run.max_force():.4g} N beyond {DIVERGENCE_FACTOR:g} f_max "
                     f"= {DIVERGENCE_FACTOR * f_max:.4g} N")
    if run.held_at is not None:
        parts.append(f"held by the force watch at t = {run.held_at:.3f} s: {run.hold_reason}")
    return {"ok": not parts, "outcome": "; ".join(parts) or "bounded, not held",
            "held_at_s": run.held_at, "max_force_N": run.max_force()}


def program_summary(run: PayloadRun, payload: float, singularity_margin: float = 4.9) -> dict:
    """From the start of the motion (after the payload was put on and identified at rest): RMS and
    worst position error [mm], and the worst relative error of the estimate where the commanded
    |ẍ_z - g| exceeds ``singularity_margin`` [m/s²] (away from the singularity of (4.4))."""
    moving = np.flatnonzero(np.linalg.norm(run.x_d[:, :3] - run.x_d[0, :3], axis=1) > 1e-6)
    k0 = int(moving[0]) if len(moving) else len(run.t) - 1
    e = 1e3 * np.linalg.norm(run.x[k0:, :3] - run.x_d[k0:, :3], axis=1)
    out = {"payload_kg": payload, "motion_start_s": float(run.t[k0]),
           "rms_position_error_mm": float(np.sqrt(np.mean(e ** 2))), "max_position_error_mm": float(e.max()),
           "max_estimate_error_percent": float("nan")}
    if payload > 0.0:                      # the identification runs in every configuration
        a_z = np.gradient(np.gradient(run.x_d[:, 2], 1e-3), 1e-3)
        away = np.abs(a_z + 9.81) > singularity_margin
        away[:k0] = False
        out["max_estimate_error_percent"] = float(100.0 * np.abs(run.m_c[away] - payload).max() / payload)
    return out


def run_program_experiment(outdir, robot="ipanema3", configs=("ik", "ik_lc"), payloads=(40.0, 80.0),
                           program: str = "payload_moves_ipanema3", progress=print, plant: str = "mismatched",
                           model=None, lc_params: LoadCompensationParams | None = None) -> dict:
    """The moving experiment (Fig. 4.7) per payload and configuration: plot and JSON summary.
    ``model``, ``lc_params``: as :func:`run_experiment`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = load_robot(model) if isinstance(model, (str, Path)) else model
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    summary = {}
    fig, ax = plt.subplots(2, 1, figsize=(7.0, 4.5), sharex=True)
    for payload in payloads:
        for config in configs:
            progress(f"{program}, {payload:g} kg, {config} ...")
            run = payload_program(robot, config, payload, program, lc_params, plant=plant, model=model)
            key = f"{config}_{payload:g}kg"
            summary[key] = {**program_summary(run, payload), **run_outcome(run, robot)}
            if not summary[key]["ok"]:
                progress(f"  NOT OK: {summary[key]['outcome']}")
            ax[0].plot(run.t, 1e3 * np.linalg.norm(run.x[:, :3] - run.x_d[:, :3], axis=1), lw=0.7, label=key)
            if CONFIGS[config][2] or CONFIGS[config][3]:
                ax[1].plot(run.t, run.m_c, lw=0.7, label=f"estimate, {key}")
                ax[1].axhline(payload, color="k", ls="--", lw=0.6)
    ax[0].set_ylabel("|r - r_d| [mm]")
    ax[1].set_ylabel("payload m_c [kg]")
    ax[1].set_xlabel("t [s]")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(outdir / "load_compensation_program.png", dpi=80)
    plt.close(fig)
    (outdir / "load_compensation_program.json").write_text(json.dumps(summary, indent=1))
    return summary
