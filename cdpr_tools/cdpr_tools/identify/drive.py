"""Drive dynamics from a recorded sweep: PT1 + dead time (3.10) or second order (5.11).

The recorded commands theta_d (``winch/command``, stamp t_k, held over one period) drive
cdpr_sim.drive_models.DriveModel, the same exact discretisation the simulator runs; the
parameters minimise the squared difference of its theta_k+1 to the encoder's ``winch/state``
stamped t_k+1 (least squares, trust region with T >= 0; the fractional dead time keeps the
residual smooth in T_d). Only the winches whose command moves take part; every drive of a robot
shares one model. Returns T_1, T_d (3.10) or T_w, zeta, T_d (5.11).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from cdpr_sim.drive_models import PT1_DEADTIME, SECOND_ORDER, DriveModel

from cdpr_tools.identify import bag_data

# start values and lower bounds of the parameters per model
_START = {PT1_DEADTIME: {"T_1": 0.01, "T_d": 0.002}, SECOND_ORDER: {"T_w": 0.01, "zeta": 0.7, "T_d": 0.002}}
AFTER_LOST = 20    # periods after a lost (interpolated) command whose states the fit leaves out
_LOWER = {PT1_DEADTIME: [0.0, 0.0], SECOND_ORDER: [1e-4, 0.05, 0.0]}


@dataclass
class DriveData:
    """Commands theta_d (K, n) of the excited winches ``cables`` and the measured theta (K + 1, n;
    NaN where the recorder lost the state)."""

    t: np.ndarray                 # (K + 1,) stamps of theta
    theta_d: np.ndarray
    theta: np.ndarray
    cables: list
    dt: float


@dataclass
class DriveFit:
    model: str
    params: dict                  # T_1, T_d or T_w, zeta, T_d [s, -]
    rms: float                    # rms of theta - model [m]
    nfev: int
    theta_model: np.ndarray = field(repr=False)


def load_data(bag, min_motion: float = 0.1) -> DriveData:
    """The sweep in ``bag``: the winches whose command range exceeds min_motion of the largest one.

    A recorder in a process of its own on a busy machine loses a message now and then (a reliable
    keep-last publisher drops what a reader has not taken in time): a lost command is interpolated
    between its neighbours, a lost state is left out of the fit (NaN in ``theta``), and so are the
    AFTER_LOST states after an interpolated command; a warning counts the losses."""
    t_c, theta_d = bag_data.commands(bag)
    state = bag_data.winch_state(bag, aligned=False)
    dt = float(np.median(np.diff(t_c)))
    dt_ns = int(round(dt * 1e9))
    # a recording of the graph starts and stops anywhere: keep the commands from the first state
    # on whose effect (the state one period later) is recorded
    ns_state, ns_c = np.rint(state.t * 1e9).astype(np.int64), np.rint(t_c * 1e9).astype(np.int64)
    keep = (ns_c >= ns_state[0]) & (ns_c + dt_ns <= ns_state[-1])
    if keep.sum() < 2:
        raise ValueError(f"no {bag_data.TOPIC_COMMAND} with the {bag_data.TOPIC_STATE} it causes in the bag")
    ns_c, theta_d = ns_c[keep], theta_d[keep]
    grid = ns_c[0] + dt_ns * np.arange((ns_c[-1] - ns_c[0]) // dt_ns + 1)     # one command a period
    # a lost command: interpolated between its neighbours (the commands of a sweep or a program are
    # smooth; holding the one before put 17 % into T_1 when every 55th of a 60 Hz chirp was lost)
    theta_d = np.column_stack([np.interp(grid, ns_c, column) for column in theta_d.T])
    span = np.ptp(theta_d, axis=0)
    cables = [int(i) for i in np.flatnonzero(span > min_motion * span.max())]
    # theta_k+1: the state stamped one period after each command, and theta_0 at the first command
    ns_next = np.concatenate([grid[:1], grid + dt_ns])
    idx = np.minimum(np.searchsorted(ns_state, ns_next), len(ns_state) - 1)
    found = ns_state[idx] == ns_next
    if not found[0]:
        raise ValueError(f"no {bag_data.TOPIC_STATE} at the first {bag_data.TOPIC_COMMAND} of the bag")
    # the states after an interpolated command answer a command that was not quite the drives': left
    # out too (AFTER_LOST periods, beyond the dead time and time constant of (3.10): T_d is 7 ms on
    # the IPAnema 3; with 5 periods, every 55th command lost still moved T_1 by 8 %)
    interpolated = np.flatnonzero(~np.isin(grid, ns_c))
    after = (interpolated[:, None] + np.arange(1, AFTER_LOST + 1)).ravel()
    measured = found.copy()
    measured[after[after < len(measured)]] = False
    theta = np.where(measured[:, None], state.theta[idx], np.nan)
    lost_c, lost_s = len(grid) - len(ns_c), int(np.count_nonzero(~found))
    if lost_c or lost_s:
        warnings.warn(f"the recorder lost {lost_c} of {len(grid)} {bag_data.TOPIC_COMMAND} (each interpolated) and {lost_s} of {len(ns_next)} {bag_data.TOPIC_STATE} (left out of the fit)",
                      stacklevel=2)
    return DriveData(ns_next * 1e-9, theta_d[:, cables], theta[:, cables], cables, dt)


def build_model(kind: str, params: dict, dt: float, m: int) -> DriveModel:
    if kind == PT1_DEADTIME:
        return DriveModel.pt1_deadtime(params["T_1"], params["T_d"], dt, m)
    if kind == SECOND_ORDER:
        return DriveModel.second_order(params["T_w"], params["zeta"], params["T_d"], dt, m)
    raise ValueError(f"unknown drive model {kind!r} (use {PT1_DEADTIME} or {SECOND_ORDER})")


def simulate(kind: str, params: dict, data: DriveData) -> np.ndarray:
    """theta (K + 1, n) of the model from the measured theta_0 under the recorded commands."""
    drive = build_model(kind, params, data.dt, len(data.cables))
    drive.reset(data.theta[0])
    out = np.empty_like(data.theta)
    out[0] = data.theta[0]
    for k, u in enumerate(data.theta_d):
        out[k + 1] = drive.step(u)
    return out


def identify(bag, kind: str = PT1_DEADTIME, start: dict | None = None) -> tuple[DriveData, DriveFit]:
    """Least-squares fit of the drive model ``kind`` to the sweep in ``bag``."""
    if kind not in _START:
        raise ValueError(f"unknown drive model {kind!r} (use {PT1_DEADTIME} or {SECOND_ORDER})")
    data = load_data(bag)
    names = list(_START[kind])
    p0 = np.array([(start or _START[kind]).get(n, _START[kind][n]) for n in names])

    measured = np.isfinite(data.theta[1:, 0])          # the states the recorder did not lose

    def residual(p):
        return (simulate(kind, dict(zip(names, p)), data) - data.theta)[1:][measured].ravel()

    res = least_squares(residual, p0, bounds=(_LOWER[kind], math.inf), x_scale=p0, diff_step=1e-4,
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    params = {n: float(v) for n, v in zip(names, res.x)}
    theta_model = simulate(kind, params, data)
    rms = float(np.sqrt(np.nanmean((theta_model - data.theta) ** 2)))
    return data, DriveFit(kind, params, rms, int(res.nfev), theta_model)


# units of the drive models' parameters, (3.10) and (5.11); zeta is a ratio
UNITS = {"T_1": " s", "T_d": " s", "T_w": " s", "zeta": ""}


def describe(fit: DriveFit) -> str:
    """``T_w = 0.0148 s, zeta = 0.536, T_d = 0.000712 s``: the parameters with their units."""
    return ", ".join(f"{k} = {v:.6g}{UNITS[k]}" for k, v in fit.params.items())


def plot(data: DriveData, fit: DriveFit, path, title: str = "") -> None:
    """PNG (1000 x 560 px): command, measured and modelled theta of the first excited winch, and the
    model error. ``title``: robot, controller and bag (:func:`cdpr_tools.identify.bag_data.run_title`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = data.theta[0, 0]
    cable = data.cables[0] + 1
    fig, (a, b) = plt.subplots(2, 1, figsize=(10, 5.6), sharex=True, height_ratios=(2, 1))
    a.plot(data.t[:-1], 1e3 * (data.theta_d[:, 0] - t0), lw=1.8, color="0.7", label="command theta_d")
    a.plot(data.t, 1e3 * (data.theta[:, 0] - t0), lw=1.2, color="tab:blue", label="encoder theta")
    a.plot(data.t, 1e3 * (fit.theta_model[:, 0] - t0), lw=0.8, ls="--", color="tab:red",
           label=f"model {fit.model}: {describe(fit)}")
    a.set_ylabel(f"winch {cable}: theta - theta(0) [mm]")
    a.legend(fontsize=8, loc="upper right")
    b.plot(data.t, 1e6 * (data.theta[:, 0] - fit.theta_model[:, 0]), lw=0.7, color="tab:red")
    b.set_ylabel("theta - model [um]")
    b.set_xlabel("t [s]")
    fig.suptitle(f"Drive fit ({'3.10' if fit.model == PT1_DEADTIME else '5.11'}), winch {cable} of "
                 f"{[c + 1 for c in data.cables]}: {title}" if title else "Drive fit", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
