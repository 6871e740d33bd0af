"""Stability margins of the cable force control and the operational space position control,
thesis sections 3.1.3 and 3.4 (Fig. 3.10-3.11), with python-control.

Open loops (the thesis' SISO models):

* CFC (3.21): G_CFC,0 = G_c,CFC G_a G_s,c G_r,c with the PI (3.19), the drive G_a (3.10) or (5.11),
  the cable G_s,c = C_i (3.13) and the feedback filter (3.20). The controller converts its force
  output with the stiffness model K_l^-1 (3.23), so the loop gain is K_p kappa with
  kappa = C_i / C_model: the plant's tangent stiffness (2.20) over the derivative of the
  controller's force -> elongation map (1 for the non-linear model, k_t / (k_spec / l_t) for the
  thesis' linear one, which the progressive cable exceeds at high forces).
* OSPC (3.17) per axis j: G_OSPC,0 = G_c,OSPC G_a G_s,p with the PI (3.16) and the platform
  (3.15) from the diagonal of K_x (2.22) and M (2.33) at a pose, tension level and payload. The
  damping: the cables' Kelvin-Voigt damping d_j = tau_c K_c,jj acts on the elongation rate, so the
  platform follows x_d through (d_j s + c_j) / (m_j s^2 + d_j s + c_j) (the thesis' (3.15) has no
  zero: it damps the absolute velocity with an identified d_j = 83.3 N s/m).

* Hand guiding (section 5.2) per axis j: the admittance (5.4)-(5.8) V = 1 / (m s^2 + d s + c) of a
  zone is driven by the user wrench (5.9) w_Adm = PT1(w - w_init - m_p xddot_d) of the period
  before. The measured wrench holds the hand h and the inertia of the *real* platform, which
  follows x_d through T = G_a G_s,p (the OSPC's platform model above): w - w_init = h - m_p xddot,
  so w_Adm = PT1(h + m_p s^2 (1 - T) x_d), a feedback of the platform's own dynamics. Its
  open loop L = -PT1 e^{-s dt} V m_p s^2 (1 - T) (without the inertia term: +PT1 e^{-s dt} V m_p s^2 T)
  is a mass ratio m_p / m times the platform's resonance 1 - T, which peaks at 1 / (2 zeta) for
  the lightly damped cable modes: the virtual mass and damping must be large enough (and the
  filter must not add too much lag) for the margins. The thesis ran hand guiding on the Mini only,
  whose 1 kg platform is light against its virtual masses; the 25 kg IPAnema 3 needs virtual
  masses of several hundred kg (docs/admittance.md).
* The dead band of (5.9) against the sensor noise: the noise sigma_s of every force sensor reaches
  the wrench as sigma_w,j = sigma_s |row j of A^T| and the PT1 passes sqrt(alpha / (2 - alpha)) of
  it (alpha = 1 - e^{-dt / T_1}); a dead band of :data:`NOISE_DEAD_BAND_SIGMAS` filtered sigmas
  keeps the noise from reaching the virtual system.

The dead time T_d becomes a Pade approximation (3.18) (order 2 as in the thesis, or higher); the
sampled controller adds half a period of zero-order hold, dt / 2, to it. The gain margin is the
factor by which K_p may grow before the loop is unstable: the critical gain is K_p times it.

Run: ``cdpr analyze stability [--help]``.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import control
import numpy as np

from cdpr_control.model import cable
from cdpr_control.control.cable_force_control import CFCParams
from cdpr_control.model.dynamics import mass_matrix
from cdpr_control.model.kinematics import inverse_kinematics
from cdpr_control.control.ospc import AXES, OSPCParams
from cdpr_control.model.robot import load_robot
from cdpr_control.model.stiffness import cable_stiffness, geometric_stiffness
from cdpr_control.analysis.eigenfrequencies import stiffness_map
from cdpr_control.analysis.energy import LEVELS
from cdpr_control.control.admittance import settings_from
from cdpr_control.control.admittance_zones import per_axis
from cdpr_control.analysis.arguments import finite, non_negative, positive, whole
from cdpr_control.model.yaml_file import load_yaml

THESIS_CFC_MARGINS = {"gain_dB": 26.7, "phase_deg": 95.5}        # Fig. 3.11
THESIS_OSPC_PHASE_MARGIN_105KG = 17.7                             # deg, z axis, Fig. 3.10
S = control.tf("s")
MIN_GAIN_MARGIN_DB, MIN_PHASE_MARGIN_DEG = 6.0, 45.0               # what a shipped parameter set must keep
NOISE_DEAD_BAND_SIGMAS = 6.0        # dead band of (5.9) in filtered noise sigmas: the peaks of a long idle time and its slow wander


def pade_delay(T: float, order: int = 2) -> control.TransferFunction:
    """e^{-T s} as a Pade all-pass (3.18) of ``order`` (2 in the thesis); 1 for T = 0."""
    if T <= 0.0:
        return control.tf(1, 1)
    num, den = control.pade(T, order)
    return control.tf(num, den)


def drive_transfer_function(robot, dt: float = 1e-3, pade_order: int = 2) -> control.TransferFunction:
    """G_a(s) (3.10) or (5.11) with the dead time plus dt / 2 of zero-order hold as a Pade (3.18)."""
    d = robot.drive
    if d.model == "pt1_deadtime":
        G = 1 / (1 + d.T_1 * S)                                     # (3.11)
    else:
        G = 1 / (1 + 2 * d.zeta * d.T_w * S + (d.T_w * S) ** 2)     # (5.11)
    return G * pade_delay(d.T_d + 0.5 * dt, pade_order)


def pi_transfer_function(K_p: float, T_i: float) -> control.TransferFunction:
    """K_p (1 + 1 / (T_i s)), (3.16) and (3.19)."""
    return K_p * (1 + 1 / (T_i * S))


def stiffness_ratio(robot, f, l_t, stiffness_model: str = "nonlinear") -> np.ndarray:
    """kappa = C_i / C_model per cable: the tangent stiffness (2.20) of the cable over the slope of
    the CFC's force -> elongation map (3.23) at the force f [N] and free length l_t [m]."""
    k_t = cable.tangent_stiffness(robot, f, l_t)
    if stiffness_model == "linear":
        return k_t / (robot.cable.k_spec_nominal / l_t)             # (2.15)
    return np.ones_like(k_t)     # d(f l_t / k_spec(f)) / df = 1 / k_t: the model's own tangent


def cfc_open_loop(robot, params: CFCParams | None = None, kappa: float = 1.0, dt: float = 1e-3,
                  pade_order: int = 2) -> control.TransferFunction:
    """G_CFC,0 (3.21) = PI (3.19) G_a (3.10)/(5.11) kappa (3.13)/(3.23) PT1 (3.20)."""
    p = params or CFCParams()
    G_r = 1 / (1 + p.T_filter * S)                                  # (3.20)
    return pi_transfer_function(p.K_p, p.T_i) * drive_transfer_function(robot, dt, pade_order) * kappa * G_r


@dataclass(frozen=True)
class Platform:
    """Per-axis platform model (3.14) at one pose: m_j, c_j (K_x diagonal) and the cable damping."""

    m: np.ndarray     # (6,) kg, kg m^2
    c: np.ndarray     # (6,) N/m, N m/rad, diagonal of K_x = K_g + K_c
    d: np.ndarray     # (6,) N s/m, tau_c diag(K_c)


def platform_model(robot, x, level: float = 0.0, payload: float = 0.0, damping_time: float = 0.002) -> Platform:
    """:class:`Platform` at pose x under the static QP forces of ``level`` (3.27) with ``payload``."""
    loaded = robot.with_payload(payload) if payload else robot
    f = stiffness_map(robot, x, level, payload).f[0]
    ik = inverse_kinematics(loaded, x)
    K_c = cable_stiffness(ik, cable.tangent_stiffness(robot, f, cable.total_free_length(robot, ik.q)))
    K_x = geometric_stiffness(ik, f) + K_c
    return Platform(np.diag(mass_matrix(loaded, x)).copy(), np.diag(K_x).copy(), damping_time * np.diag(K_c))


def ospc_open_loop(robot, platform: Platform, axis: int, params: OSPCParams | None = None, dt: float = 1e-3,
                   pade_order: int = 2, absolute_damping: bool = False) -> control.TransferFunction:
    """G_OSPC,0 (3.17) of one axis = PI (3.16) G_a (3.10)/(5.11) G_s,p (3.15).

    The damping acts on the cables' elongation rate (a zero at -c/d), or with ``absolute_damping``
    on the platform velocity as printed in (3.15)."""
    p = params or OSPCParams()
    m, c, d = platform.m[axis], platform.c[axis], platform.d[axis]
    G_sp = (c if absolute_damping else d * S + c) / (m * S**2 + d * S + c)
    return pi_transfer_function(float(p.K_p[axis]), float(p.T_i[axis])) * drive_transfer_function(robot, dt, pade_order) * G_sp


@dataclass(frozen=True)
class Margins:
    """Gain margin (factor and dB), phase margin [deg] and their crossover frequencies [rad/s]."""

    gain: float
    gain_dB: float
    phase_deg: float
    w_phase_crossover: float     # where the phase is -180 deg (gain margin read here)
    w_gain_crossover: float      # where |L| = 1 (phase margin read here)

    @property
    def stable(self) -> bool:
        return self.gain > 1.0 and self.phase_deg > 0.0


def margins(L: control.TransferFunction) -> Margins:
    """Margins of the open loop L (python-control's stability_margins)."""
    gm, pm, _, w180, wc, _ = control.stability_margins(L)
    return Margins(float(gm), float(20 * np.log10(gm)), float(pm), float(w180), float(wc))


def closed_loop_stable(L: control.TransferFunction) -> bool:
    """All poles of L / (1 + L) in the left half plane."""
    return bool(np.all(np.real(control.poles(control.feedback(L, 1))) < 0.0))


def cfc_kappa(robot, x, level: float, payload: float, stiffness_model: str) -> float:
    """Largest kappa over the cables at pose x under the static QP forces (the least stable cable)."""
    f = stiffness_map(robot, x, level, payload).f[0]
    l_t = cable.total_free_length(robot, inverse_kinematics(robot, x).q)
    return float(np.max(stiffness_ratio(robot, f, l_t, stiffness_model)))


def admittance_open_loop(robot, platform: Platform, axis: int, c: float, d: float, m: float, T_filter: float,
                         dt: float = 1e-3, pade_order: int = 2, inertia_compensation: bool = True) -> control.TransferFunction:
    """L of the hand-guiding loop of one axis and one zone (c, d, m of (5.4)), negative feedback
    form (closed loop V / (1 + L)): -PT1 e^{-s dt} V m_p s^2 (1 - T) with the inertia term of (5.9),
    +PT1 e^{-s dt} V m_p s^2 T without; T = G_a (3.10)/(5.11) G_s,p (3.15) the platform following x_d."""
    m_p, c_p, d_p = platform.m[axis], platform.c[axis], platform.d[axis]
    T = drive_transfer_function(robot, dt, pade_order) * (d_p * S + c_p) / (m_p * S**2 + d_p * S + c_p)
    # V s^2 written out, so that the free zone's integrator (c = 0) cancels exactly
    V_s2 = control.tf([1.0, 0.0], [m, d]) if c == 0.0 else control.tf([1.0, 0.0, 0.0], [m, d, c])
    loop = (1 / (1 + T_filter * S)) * pade_delay(dt, pade_order) * V_s2 * m_p
    return -loop * (1 - T) if inertia_compensation else loop * T


def admittance_margins(robot, x, zones, T_filter: float, payload: float = 0.0, damping_time: float = 0.002,
                       dt: float = 1e-3, pade_order: int = 2, inertia_compensation: bool = True) -> list[list[Margins]]:
    """Margins of :func:`admittance_open_loop` at pose x, per zone of ``zones`` (a ZoneSet; the
    wall zone with its spring) and axis: [zone][axis]. ``robot`` without the payload."""
    plat = platform_model(robot, x, 0.0, payload, damping_time)
    return [[margins(admittance_open_loop(robot, plat, j, float(zone.c[j]), float(zone.d[j]), float(zone.m[j]),
                                          T_filter, dt, pade_order, inertia_compensation)) for j in range(6)]
            for zone in zones.zones]


def wrench_noise(robot, x, T_filter: float, dt: float = 1e-3, noise_std: float | None = None) -> np.ndarray:
    """Standard deviation (6,) [N, N m] of the sensor noise in the PT1-filtered wrench (5.9) at
    pose x: sigma_s |row of A^T| sqrt(alpha / (2 - alpha)); noise_std default: the robot file's."""
    sigma = robot.sensor.noise_std if noise_std is None else noise_std
    AT = inverse_kinematics(robot, x).AT
    alpha = 1.0 if T_filter == 0.0 else 1.0 - np.exp(-dt / T_filter)
    return sigma * np.linalg.norm(AT, axis=1) * np.sqrt(alpha / (2.0 - alpha))


def admittance_report(robot, x, values: dict, payload: float, damping_time: float, dt: float,
                      pade_order: int) -> list[str]:
    """Lines of the hand-guiding loop's margins per axis (worst zone) and the dead band against
    the filtered sensor noise, for the flat ``admittance_controller`` parameters ``values``."""
    params, zones, _ = settings_from(values, robot, check_workspace=False)
    T_f = params.user.T_filter
    per_zone = admittance_margins(robot, x, zones, T_f, payload, damping_time, dt, pade_order,
                                  params.user.inertia_compensation)
    noise = wrench_noise(robot, x, T_f, dt)
    band = per_axis(params.user.dead_band, "dead_band")
    lines = [f"hand guiding (5.4)-(5.9): T_filter {T_f * 1e3:g} ms, zones {', '.join(z.name for z in zones.zones)}; "
             f"need >= {MIN_GAIN_MARGIN_DB:g} dB, {MIN_PHASE_MARGIN_DEG:g} deg",
             "  axis  m       d         worst zone  GM [dB]  PM [deg]  noise sigma  dead band / sigma"
             "  (PM 999: |L| < 1 everywhere)"]
    for j in range(6):
        k = min(range(len(zones.zones)), key=lambda i: admittance_slack(per_zone[i][j]))
        mg, zone = per_zone[k][j], zones.zones[k]
        verdict = "ok" if admittance_slack(mg) >= 0.0 and band[j] >= NOISE_DEAD_BAND_SIGMAS * noise[j] else "FAILS"
        lines.append(f"  {AXES[j]:4s}  {zone.m[j]:6.4g}  {zone.d[j]:8.4g}  {zone.name:10s}  {mg.gain_dB:7.2f}"
                     f"  {min(mg.phase_deg, 999.0):8.1f}  {noise[j]:11.3g}  {band[j] / noise[j]:6.1f}  {verdict}")
    return lines


def admittance_slack(m: Margins) -> float:
    """How far margins exceed what a shipped set needs, relative (< 0: they fall short)."""
    return min(m.gain_dB / MIN_GAIN_MARGIN_DB, m.phase_deg / MIN_PHASE_MARGIN_DEG) - 1.0


def cfc_instability(robot, params: CFCParams, dt: float = 1e-3) -> str | None:
    """Why the CFC loop (3.21) with ``params`` is unstable by the margins, or None when it is stable
    (gain margin above 0 dB and phase margin above 0 deg). At home under the minimal tension (the
    shipped tension level); kappa (3.23) is the least stable cable's. One transfer function, about
    0.1 s: for a node's parameter validation, not for every period."""
    kappa = cfc_kappa(robot, robot.home, 0.0, 0.0, params.stiffness_model)
    mg = margins(cfc_open_loop(robot, params, kappa, dt))
    if mg.stable:
        return None
    return (f"the cable force control (3.21) with K_p {params.K_p:g}, T_i {params.T_i:g} s is unstable by the stability "
            f"analysis (thesis 3.4, at home): gain margin {mg.gain_dB:.1f} dB, phase margin {mg.phase_deg:.1f} deg "
            f"(both must be positive)")


def ospc_instability(robot, params: OSPCParams, dt: float = 1e-3) -> str | None:
    """Why the OSPC loop (3.17) of some axis with ``params`` is unstable by the margins, or None
    (see :func:`cfc_instability`): the platform model (3.15) at home under the minimal tension, six
    transfer functions, about 0.3 s."""
    platform = platform_model(robot, robot.home, 0.0, 0.0)
    for j in range(6):
        mg = margins(ospc_open_loop(robot, platform, j, params, dt))
        if not mg.stable:
            return (f"the operational-space position control (3.17) of axis {AXES[j]} with K_p {float(params.K_p[j]):g}, "
                    f"T_i {float(params.T_i[j]):g} s is unstable by the stability analysis (thesis 3.4, at home): "
                    f"gain margin {mg.gain_dB:.1f} dB, phase margin {mg.phase_deg:.1f} deg (both must be positive)")
    return None


def report(robot, x, cfc: CFCParams, ospc: OSPCParams, payload: float, damping_time: float, dt: float,
           pade_order: int) -> list[str]:
    lines = [f"{robot.name} at x = {np.round(x, 3).tolist()}, payload {payload:g} kg, control period {dt * 1e3:g} ms",
             f"CFC (3.21): K_p {cfc.K_p:g}, T_i {cfc.T_i:g} s, T_filter {cfc.T_filter:g} s, "
             f"stiffness model {cfc.stiffness_model}; thesis (IPAnema 3, Fig. 3.11): "
             f"{THESIS_CFC_MARGINS['gain_dB']} dB, {THESIS_CFC_MARGINS['phase_deg']} deg",
             "  tension  kappa   GM [dB]  PM [deg]  w_180 [rad/s]  critical K_p"]
    for name, level in LEVELS.items():
        kappa = cfc_kappa(robot, x, level, payload, cfc.stiffness_model)
        mg = margins(cfc_open_loop(robot, cfc, kappa, dt, pade_order))
        lines.append(f"  {name:7s}  {kappa:5.3f}  {mg.gain_dB:7.2f}  {mg.phase_deg:8.1f}  {mg.w_phase_crossover:13.1f}"
                     f"  {cfc.K_p * mg.gain:10.3f}")
    lines.append(f"OSPC (3.17) per axis, K_p {np.round(ospc.K_p, 3).tolist()}, T_i {np.round(ospc.T_i, 3).tolist()} s, "
                 f"cable damping tau_c {damping_time * 1e3:g} ms")
    lines.append("  tension  axis  f_n [Hz]  GM [dB]  PM [deg]  critical K_p")
    for name, level in LEVELS.items():
        plat = platform_model(robot, x, level, payload, damping_time)
        for j in range(6):
            mg = margins(ospc_open_loop(robot, plat, j, ospc, dt, pade_order))
            f_n = np.sqrt(plat.c[j] / plat.m[j]) / (2 * np.pi)
            lines.append(f"  {name:7s}  {AXES[j]:4s}  {f_n:8.2f}  {mg.gain_dB:7.2f}  {mg.phase_deg:8.1f}"
                         f"  {ospc.K_p[j] * mg.gain:10.3f}")
    return lines


def plot(robot, loops: dict, path, subtitle: str = "") -> None:
    """Bode (left) and Nyquist (right) diagrams of labelled open loops (Fig. 3.10-3.11), 990 x 585 px.
    Every loop's label (with its margins) is in the Nyquist legend; ``subtitle`` names the
    controller parameters and the operating point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w = np.logspace(-1, 4, 8000)             # dense enough for a smooth Nyquist curve at the resonances
    fig = plt.figure(figsize=(11, 6.5))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.25, 1))
    a_mag = fig.add_subplot(grid[0, 0])
    a_ph = fig.add_subplot(grid[1, 0], sharex=a_mag)
    a_ny = fig.add_subplot(grid[:, 1])
    for label, L in loops.items():
        resp = L(1j * w)
        mg = margins(L)
        text = f"{label}: GM {mg.gain_dB:.1f} dB, PM {mg.phase_deg:.1f} deg"
        a_mag.semilogx(w, 20 * np.log10(np.abs(resp)), label=text)
        a_ph.semilogx(w, np.degrees(np.unwrap(np.angle(resp))), label=text)
        a_ny.plot(resp.real, resp.imag, label=text)
    a_mag.axhline(0.0, color="k", lw=0.5)
    a_mag.set_ylabel("|L(j omega)| [dB]")
    a_mag.set_title("Bode magnitude", fontsize=9)
    a_ph.axhline(-180.0, color="k", lw=0.5)
    a_ph.set_ylabel("phase of L(j omega) [deg]")
    a_ph.set_title("Bode phase (-180 deg marked)", fontsize=9)
    a_ph.set_xlabel("omega [rad/s]")
    for ax in (a_mag, a_ph):
        ax.grid(True, which="both", alpha=0.3)
    a_ny.plot([-1], [0], "r+", ms=12, label="critical point -1")
    a_ny.set_xlim(-2.0, 1.5)
    a_ny.set_ylim(-2.5, 1.0)
    a_ny.set_xlabel("Re L(j omega) [-]")
    a_ny.set_ylabel("Im L(j omega) [-]")
    a_ny.grid(True, alpha=0.3)
    a_ny.set_title("Nyquist", fontsize=9)
    a_ny.legend(fontsize=7, loc="upper right")
    fig.suptitle(f"{robot.name}: open loops, stability margins" + (f"\n{subtitle}" if subtitle else ""), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _parameter_file(robot, path=None) -> dict:
    """The ROS parameter file ``path``, default the robot's shipped params/<robot file stem>.yaml."""
    import yaml
    from importlib import resources

    if path is None:
        text = resources.files("cdpr_control").joinpath("params", f"{Path(str(robot.file)).stem}.yaml").read_text()
        return yaml.safe_load(text) or {}
    data = load_yaml(path, "parameter file") or {}        # errors name the file
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a parameter file is a mapping of node names, not a {type(data).__name__}")
    return data


def admittance_values(robot, path=None) -> dict:
    """The flat ``admittance_controller`` parameters of a parameter file (see :func:`controller_params`)."""
    return dict(((_parameter_file(robot, path).get("admittance_controller") or {}).get("ros__parameters")) or {})


def controller_params(robot, path=None) -> tuple[CFCParams, OSPCParams, float]:
    """(CFC, OSPC parameters, control period) from a ROS parameter file; default: the robot's
    shipped params/<robot file stem>.yaml. Keys the dataclasses do not know are left out."""
    from dataclasses import fields

    data = _parameter_file(robot, path)

    def section(node: str, cls):
        values = (data.get(node) or {}).get("ros__parameters") or {}
        names = {f.name for f in fields(cls)}
        return cls(**{k: (np.asarray(v, dtype=float) if isinstance(v, list) else v)
                      for k, v in values.items() if k in names})

    dt = float(((data.get("/**") or {}).get("ros__parameters") or {}).get("control_period", 1e-3))
    return section("cable_force_controller", CFCParams), section("ospc", OSPCParams), dt


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="cdpr analyze stability",
                                description="Gain and phase margins of CFC (3.21), OSPC (3.17) (sections 3.1.3, 3.4) "
                                            "and hand guiding (5.4)-(5.9) (section 5.2).")
    p.add_argument("--robot", default="ipanema3", help="robot name or YAML path")
    p.add_argument("--params", help="controller parameter file (default: the robot's shipped params/<robot>.yaml)")
    p.add_argument("--pose", type=finite, nargs="+", help="x y z [a b c] (default: home)")
    p.add_argument("--payload", type=non_negative, default=0.0, help="payload [kg]")
    p.add_argument("--damping-time", type=positive, default=0.002,
                   help="cable Kelvin-Voigt time constant tau_c [s] (the simulator's default)")
    p.add_argument("--pade-order", type=whole(0), default=2, help="order of the Pade approximation (3.18)")
    p.add_argument("--plot-dir", help="write stability_<robot>.png (Bode and Nyquist) here")
    p.add_argument("--plot-payloads", type=non_negative, nargs="+", default=[0.0, 80.0],
                   help="payloads [kg] of the OSPC z loops in the plot (default 0 80: m_p 25 and 105 kg, Fig. 3.10)")
    args = p.parse_args(argv)
    robot = load_robot(args.robot)
    x = np.array(robot.home, dtype=float)
    if args.pose:
        x[:len(args.pose)] = args.pose
    cfc, ospc, dt = controller_params(robot, args.params)
    print("\n".join(report(robot, x, cfc, ospc, args.payload, args.damping_time, dt, args.pade_order)))
    print("\n".join(admittance_report(robot, x, admittance_values(robot, args.params), args.payload,
                                       args.damping_time, dt, args.pade_order)))
    if args.plot_dir:
        out = Path(args.plot_dir)
        out.mkdir(parents=True, exist_ok=True)
        loops = {"CFC": cfc_open_loop(robot, cfc, cfc_kappa(robot, x, 0.0, args.payload, cfc.stiffness_model),
                                      dt, args.pade_order)}
        for payload in args.plot_payloads:
            plat = platform_model(robot, x, 0.0, payload, args.damping_time)
            loops[f"OSPC z, payload {payload:g} kg"] = ospc_open_loop(robot, plat, 2, ospc, dt, args.pade_order)
        path = out / f"stability_{Path(str(robot.file)).stem}.png"
        plot(robot, loops, path, f"CFC K_p {cfc.K_p:g}, T_i {cfc.T_i:g} s; OSPC z K_p {float(ospc.K_p[2]):g}, "
                                 f"T_i {float(ospc.T_i[2]):g} s; at x = {np.round(x[:3], 3).tolist()} m, minimal tension")
        print(f"wrote {path}")
    return 0
