"""Pulley friction per cable by Levenberg-Marquardt on a recorded run, thesis (3.45).

For cable i the parameters p = (mu, sigma, F_pv, epsilon) minimise

    sum_k (Psi_PF(F_s,k, thetadot_k, theta_k, beta_np,k) + epsilon - F_np,k)^2          (3.45)

with Psi_PF the friction model cdpr_control.model.friction.PulleyFriction.platform_force (3.30)-(3.44),
run over the whole recording because the Dahl state (3.43) carries over from sample to sample.
F_s, theta, thetadot come from ``winch/state``, the reference force at the platform F_np from
``ground_truth/cable_forces`` (the extra sensor of section 3.7.2), beta_np from the inverse
kinematics (2.6) of the recorded pose. epsilon absorbs a calibration offset between the two
sensors and is not part of the compensation's parameters.

Speed: one pass over the samples evaluates the model for several parameter sets at once (the
model is vectorised over its columns), so a residual and its forward-difference Jacobian cost one
pass. sigma is fitted as log(sigma) to keep it positive; the wrap angle is re-evaluated when the
platform moved ``beta_refresh`` m, as the simulator freezes its pulley IK between refreshes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from cdpr_control.model.friction import PulleyFriction
from cdpr_control.model.kinematics import inverse_kinematics

from cdpr_tools.identify import bag_data

# relative forward-difference steps of (mu, log sigma, F_pv)
_STEPS = np.array([1e-3, 1e-3, 1e-3])


@dataclass
class FrictionData:
    """Samples (N, m) of one run: encoder theta, thetadot, sensor F_s, reference f_ref, wrap angle beta."""

    t: np.ndarray
    theta: np.ndarray
    thetadot: np.ndarray
    F_s: np.ndarray
    f_ref: np.ndarray
    beta: np.ndarray


@dataclass
class FrictionFit:
    """Identified parameters of one cable (0-based index) and the fit quality [N]."""

    cable: int
    mu: float
    sigma: float
    F_pv: float
    epsilon: float
    rms_without: float          # rms of F_np - f_w (no friction model, offset removed)
    rms_with: float             # rms of the residual of (3.45)
    nfev: int
    model: np.ndarray = field(repr=False)    # Psi_PF + epsilon over the run
    f_w: np.ndarray = field(repr=False)      # the sensor line alone (3.40) + epsilon, for comparison


def wrap_angles(robot, x, beta_refresh: float = 1e-3) -> np.ndarray:
    """beta_np (N, m) from the IK (2.6) at poses x (N, 6), held until the platform moved beta_refresh m."""
    beta = np.empty((len(x), robot.m))
    anchor = None
    for k, xk in enumerate(x):
        if anchor is None or np.linalg.norm(xk[:3] - anchor) > beta_refresh:
            anchor, current = xk[:3], inverse_kinematics(robot, xk).beta
        beta[k] = current
    return beta


def load_data(bag, robot, beta_refresh: float = 1e-3) -> FrictionData:
    """The friction run of ``bag`` (cdpr_tools.bag.BagReader) for ``robot``."""
    w = bag_data.winch_state(bag)
    x = bag_data.poses(bag, w.t)
    return FrictionData(w.t, w.theta, w.thetadot, w.F_s, bag_data.reference_forces(bag, w.t),
                        wrap_angles(robot, x, beta_refresh))


def model_forces(robot, data: FrictionData, cable: int, params, v_eps: float = 0.0, jit=None) -> np.ndarray:
    """Psi_PF (N, k) of ``cable`` for k parameter sets ``params`` (k, 3) = (mu, sigma, F_pv), one pass."""
    params = np.atleast_2d(np.asarray(params, dtype=float))
    k = params.shape[0]
    fr = robot.friction
    model = PulleyFriction(params[:, 0], params[:, 1], params[:, 2], np.full(k, fr.n_pulleys[cable]),
                           fr.beta_inner, robot.sensor.beta_1, np.full(k, data.theta[0, cable]), v_eps, jit)
    out = np.empty((len(data.t), k))
    beta_col = data.beta[:, cable]
    beta = None
    for j, (F_s, theta, thetadot, b) in enumerate(zip(data.F_s[:, cable], data.theta[:, cable],
                                                      data.thetadot[:, cable], beta_col)):
        if beta is None or b != beta[0]:          # a new read-only array only when beta changes
            beta = np.full(k, b)
            beta.setflags(write=False)
        out[j] = model.platform_force(np.full(k, F_s), np.full(k, theta), np.full(k, thetadot), beta)
    return out


def fit_cable(robot, data: FrictionData, cable: int, p0=(0.02, 1000.0, 1.0), v_eps: float = 0.0,
              jit=None) -> FrictionFit:
    """Levenberg-Marquardt (3.45) for one cable from the start values p0 = (mu, sigma, F_pv)."""
    f_ref = data.f_ref[:, cable]
    cache = {}

    def evaluate(q):
        key = q.tobytes()
        if key not in cache:
            mu, log_sigma, F_pv, eps = q
            base = np.array([mu, log_sigma, F_pv])
            h = _STEPS * np.maximum(np.abs(base), [1e-2, 1.0, 1.0])
            sets = np.vstack([base, base + np.diag(h)])
            sets[:, 1] = np.exp(sets[:, 1])
            F = model_forces(robot, data, cable, sets, v_eps, jit)
            r = F[:, 0] + eps - f_ref
            J = np.column_stack([(F[:, 1:] - F[:, :1]) / h, np.ones_like(r)])
            cache.clear()
            cache[key] = (r, J)
        return cache[key]

    f_w = model_forces(robot, data, cable, [[0.0, 1.0, 0.0]], v_eps, jit)[:, 0]   # no friction
    eps0 = float(np.mean(f_ref - f_w))
    q0 = np.array([p0[0], np.log(p0[1]), p0[2], eps0])
    res = least_squares(lambda q: evaluate(q)[0], q0, jac=lambda q: evaluate(q)[1], method="lm")
    mu, log_sigma, F_pv, eps = res.x
    r = evaluate(res.x)[0]
    return FrictionFit(cable, float(mu), float(np.exp(log_sigma)), float(F_pv), float(eps),
                       float(np.std(f_ref - f_w)), float(np.sqrt(np.mean(r**2))), int(res.nfev), r + f_ref,
                       f_w + eps)


def identify(bag, robot, cables=None, p0=(0.02, 1000.0, 1.0), v_eps: float = 0.0, progress=None,
             jit=None) -> tuple[FrictionData, list[FrictionFit]]:
    """Fit (3.45) for each cable of ``cables`` (default all); progress(line) after each cable."""
    data = load_data(bag, robot)
    fits = []
    for i in range(robot.m) if cables is None else cables:
        fits.append(fit_cable(robot, data, i, p0, v_eps, jit))
        if progress:
            f = fits[-1]
            progress(f"cable {i + 1}: mu {f.mu:.4f}  sigma {f.sigma:.0f} N/m  F_pv {f.F_pv:.3f} N s/m  "
                     f"epsilon {f.epsilon:+.3f} N  rms {f.rms_without:.3f} -> {f.rms_with:.3f} N")
    return data, fits


def parameter_file(fits: list[FrictionFit]) -> dict:
    """The friction_compensation node's parameters in the standard ROS 2 layout (epsilon left out)."""
    fits = sorted(fits, key=lambda f: f.cable)
    return {"friction_compensation": {"ros__parameters": {
        "mu": [f.mu for f in fits], "sigma": [f.sigma for f in fits], "F_pv": [f.F_pv for f in fits]}}}


def write_parameter_file(fits: list[FrictionFit], path) -> None:
    import yaml

    with open(path, "w") as out:
        out.write("# Pulley friction identified by `cdpr identify friction` (thesis (3.45)); units SI.\n")
        yaml.safe_dump(parameter_file(fits), out, default_flow_style=None, sort_keys=False)


def plot(data: FrictionData, fits: list[FrictionFit], path, title: str = "") -> None:
    """PNG (1200 x 800 px, cables in two columns): per cable the reference force F_np, the sensor line
    without friction f_w (3.40) and the fitted model (3.44) over time. The reference is drawn wide, light
    and below, the model narrow and black on top, so both stay visible where they agree.
    ``title``: robot, controller and bag (:func:`cdpr_tools.identify.bag_data.run_title`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = (len(fits) + 1) // 2
    fig, axes = plt.subplots(rows, 2 if len(fits) > 1 else 1, figsize=(12, 1.9 * rows + 0.8), sharex=True,
                             squeeze=False)
    for ax, f in zip(axes.T.ravel(), fits):
        i = f.cable
        ax.plot(data.t, f.f_w, lw=0.5, color="tab:orange", alpha=0.8, label="f_w (3.40) + epsilon: sensor, no friction")
        ax.plot(data.t, data.f_ref[:, i], lw=2.6, color="tab:blue", alpha=0.45, label="reference F_np at the platform")
        ax.plot(data.t, f.model, lw=0.5, color="black", label="fitted model (3.44) + epsilon")
        ax.set_ylabel(f"cable {i + 1} force [N]", fontsize=8)
        ax.set_title(f"cable {i + 1}: mu {f.mu:.4f}, sigma {f.sigma:.0f} N/m, F_pv {f.F_pv:.2f} N s/m, "
                     f"rms {f.rms_without:.2f} -> {f.rms_with:.2f} N", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in axes.T.ravel()[len(fits):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]", fontsize=8)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", ncol=3, fontsize=8, bbox_to_anchor=(0.5, 0.965))
    fig.suptitle(f"Pulley friction fit (3.45): {title}" if title else "Pulley friction fit (3.45)", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(path, dpi=100)
    plt.close(fig)
