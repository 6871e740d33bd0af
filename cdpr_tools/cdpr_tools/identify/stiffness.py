"""Cable stiffness k0, k1, k2 of (2.16) from force/elongation data at rest.

At rest the elongation of cable i is dq = IK{x} - theta (2.24) up to the encoder's calibration
offset delta_i (section 2.3.2: the encoders read IK{home} under the start-up tension), and (2.17)
gives dq = f l_t / (k0 + k1 f + k2 f^2) with l_t = q + l_0 (2.14). Least squares over k0, k1, k2
(one cable type for the robot), delta_i and a relative correction g_i of l_t per cable on the
samples where the command has stood still for ``settle`` s (the platform has come to rest); with the
cable force control in the loop (a program run on the graph) the command is never exactly still, so
"still" is moving slower than ``rate`` (1 mm/s: the CFC's noise-driven motion at rest is about 0.6
mm/s on the Mini, its tension steps 3-8 mm/s).
f: the sensor forces through the loop's friction compensation (3.44), or the reference forces.

What a real robot (and the simulator's mismatched plant) adds to the perfect model, and how the
fit copes:

* geometry errors of millimetres, as large as the Mini's elongations: at one pose they change
  IK{x} by a constant per cable, which delta_i absorbs;
* errors of l_0 (2.14) of ~2 %: they scale each cable's elongation; g_i absorbs them. Only
  k_spec / l_t is observable, so a common scale of all l_t is k0's: the g_i are constrained to a
  zero mean (the lengths are measured without a common bias);
* slack cables: (2.17) holds for taut cables only (a slack cable reads f ~ 0 at any negative
  elongation), so only samples with f >= ``f_taut`` enter;
* cable settlement under load (section 4.1.3) adds lasting length while a cable carries more than
  before: the run steps the tension down from a pre-load, whose samples (and all before them: the
  rest stretch at the highest forces and those before it) are left out (``preload``), so the data see
  no settlement.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from cdpr_control.model import cable
from cdpr_control.model.kinematics import inverse_kinematics

from cdpr_tools.identify import bag_data


@dataclass
class StiffnessFit:
    k0: float                    # N
    k1: float                    # -
    k2: float                    # 1/N
    delta: np.ndarray            # (m,) m, encoder offsets
    g: np.ndarray                # (m,) -, relative corrections of l_t (zero mean)
    rms: float                   # m, elongation residual
    n_samples: int               # resting samples (each with the taut cables of that sample)


def resting_mask(t, t_c, theta_d, settle: float, rate: float = 0.0) -> np.ndarray:
    """Samples at stamps t whose command has moved no faster than ``rate`` [m/s] (per winch, from one
    period to the next) for at least ``settle`` s. rate 0: the command has not changed at all, as in
    the experiments' holds; a command with a force control in the loop is never exactly still."""
    dt = np.diff(t_c)
    moved = np.concatenate([[True], np.any(np.abs(np.diff(theta_d, axis=0)) > rate * dt[:, None], axis=1)])
    last_change = np.maximum.accumulate(np.where(moved, t_c, -np.inf))
    idx = np.clip(np.searchsorted(t_c, t, side="right") - 1, 0, None)
    return t - last_change[idx] >= settle


def after_preload(mask, force_sum) -> np.ndarray:
    """``mask`` without its rest stretches up to and including the one at the highest mean total force
    (the pre-load, during which the cables settle, section 4.1.3)."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if len(starts) == 0:
        return mask
    preload = int(np.argmax([force_sum[a:b].mean() for a, b in zip(starts, ends)]))
    kept = mask.copy()
    kept[:ends[preload]] = False
    return kept


def identify(bag, robot, friction_params: dict | None = None, use_reference: bool = False,
             settle: float = 0.2, start=(20000.0, 0.0, 0.0), f_taut: float = 1.0,
             preload: bool = True, rate: float = 1e-3) -> StiffnessFit:
    """Fit (2.16) to the resting samples of ``bag`` (the command moving slower than ``rate`` m/s for
    ``settle`` s); preload: leave out the rest stretches up to the one at the highest forces."""
    from cdpr_tools.identify.friction import load_data
    from cdpr_tools.identify.mass import compensated_forces

    data = load_data(bag, robot)
    t_c, theta_d = bag_data.commands(bag)
    mask = resting_mask(data.t, t_c, theta_d, settle, rate)
    if preload:                                       # the cables settle during the pre-load (4.1.3)
        mask = after_preload(mask, data.F_s.sum(axis=1))
    if mask.sum() < 10:
        raise ValueError("no samples at rest after the pre-load: hold the command still for longer than "
                         f"{settle} s after the highest tension")
    dt = float(np.median(np.diff(data.t)))
    f = (data.f_ref if use_reference else compensated_forces(robot, data, dt, friction_params))[mask]
    x = bag_data.poses(bag, data.t)[mask]
    q = np.array([inverse_kinematics(robot, xk).q for xk in x])
    dq_enc = q - data.theta[mask]                     # elongation without the encoder offset
    l_t = cable.total_free_length(robot, q)
    taut = f >= f_taut                                # (2.17) holds for taut cables only
    if np.any(taut.sum(axis=0) < 10):
        raise ValueError(f"a cable has fewer than 10 samples at rest with f >= {f_taut} N")
    m = robot.m
    scale = np.array([start[0], 100.0, 1.0])

    def corrections(p):
        g = p[3 + m:] * 1e-2
        return p[3:3 + m] * 1e-3, np.r_[g, -np.sum(g)]          # delta [m]; g with zero mean

    def residual(p):
        k0, k1, k2 = p[:3] * scale
        r = dataclasses.replace(robot, cable=dataclasses.replace(robot.cable, k0=k0, k1=k1, k2=k2))
        delta, g = corrections(p)
        return (cable.elongation_from_force(r, f, l_t * (1.0 + g)) - dq_enc - delta)[taut]

    p0 = np.concatenate([np.array(start) / scale, np.zeros(2 * m - 1)])
    res = least_squares(residual, p0, method="lm", xtol=1e-12, ftol=1e-12)
    k0, k1, k2 = res.x[:3] * scale
    delta, g = corrections(res.x)
    return StiffnessFit(float(k0), float(k1), float(k2), delta, g,
                        float(np.sqrt(np.mean(res.fun**2))), int(mask.sum()))


def write_robot_file(robot_name_or_path, fit: StiffnessFit, out) -> "Path":
    """A copy of the robot file with the identified cable: k0, k1, k2 of (2.16) and l_0 + g_i l_t,i
    (the free-length correction of the fit, taken at the robot's home, where
    :func:`experiments.record_stiffness_run` records: l_t (1 + g) = q + l_0 + g l_t (2.14)).
    The result loads with :func:`cdpr_control.model.robot.load_robot` (checked); comments are not kept."""
    from pathlib import Path

    import yaml

    from cdpr_control.model.robot import load_robot, robot_path

    path = robot_path(robot_name_or_path)
    robot = load_robot(path)
    data = yaml.safe_load(path.read_text())
    l_t = cable.total_free_length(robot, inverse_kinematics(robot, robot.home).q)
    data["cable"].update(k0=float(fit.k0), k1=float(fit.k1), k2=float(fit.k2))
    data["geometry"]["l_0"] = [float(v) for v in robot.l_0 + fit.g * l_t]
    data["name"] = f"{robot.name} (identified cable)"
    out = Path(out)
    out.write_text("# robot file with the cable identified by `cdpr identify stiffness` (2.16)\n"
                   + yaml.safe_dump(data, sort_keys=False))
    load_robot(out)
    return out
