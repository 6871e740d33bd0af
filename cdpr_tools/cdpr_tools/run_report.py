"""Summary and plots of one closed-loop run, from its recorded messages.

The main job (``cdpr demo``) and ``cdpr plot`` use the same functions: messages grouped by topic
become aligned arrays (:class:`RunData`), then :func:`summarize` gives the numbers the demo prints
and :func:`plot_run` writes the PNGs. Pose errors compare the ground truth ("laser tracker") with
the set-point x_d of the same control period, as the thesis does (section 4.2).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_control.ros.conversions import pose_from_msg

TOPICS = {
    "setpoint": "setpoint",
    "truth_pose": "ground_truth/pose",
    "truth_forces": "ground_truth/cable_forces",
    "forces": "cable_forces",
    "distribution": "force_distribution",
    "cfc": "cable_force_controller/state",
    "ospc": "ospc/state",
}


@dataclass
class RunData:
    """Time series on the common stamps of set-point and ground truth (t in s from the first)."""

    t: np.ndarray             # (N,)
    x_d: np.ndarray           # (N, 6) set-point
    x: np.ndarray             # (N, 6) ground-truth pose
    f: np.ndarray             # (N, m) true cable forces at the platform
    f_min: np.ndarray         # (m,)
    f_max: np.ndarray         # (m,)
    f_d: np.ndarray | None    # (N, m) desired forces, when recorded
    dq_cfc: np.ndarray | None  # (N, m) CFC output, when recorded
    x_ospc: np.ndarray | None  # (N, 6) OSPC output, when recorded


def _by_stamp(messages) -> dict[int, object]:
    return {m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec: m for m in messages}


def run_data(messages: dict[str, list]) -> RunData:
    """Align the recorded messages (topic -> list of messages, topic names as in TOPICS)."""
    missing = [TOPICS[k] for k in ("setpoint", "truth_pose", "truth_forces") if not messages.get(TOPICS[k])]
    if missing:
        raise ValueError(f"run has no messages on {', '.join(missing)}")
    series = {k: _by_stamp(messages.get(topic, [])) for k, topic in TOPICS.items()}
    stamps = sorted(set(series["setpoint"]) & set(series["truth_pose"]) & set(series["truth_forces"]))
    if not stamps:
        raise ValueError("set-point and ground truth share no stamps (was the simulator in lockstep?)")
    t = (np.array(stamps) - stamps[0]) * 1e-9
    x_d = np.array([pose_from_msg(series["setpoint"][s].pose) for s in stamps])
    x = np.array([pose_from_msg(series["truth_pose"][s].pose) for s in stamps])
    forces = [series["truth_forces"][s] for s in stamps]
    f = np.array([m.f for m in forces])

    def optional(key, field):
        """A recorded series on the common stamps; periods it lacks (e.g. t = 0) repeat the previous."""
        got = series[key]
        if not got:
            return None
        rows, last = [], None
        for s in stamps:
            last = got.get(s, last)
            rows.append(None if last is None else list(getattr(last, field)))
        width = next((len(r) for r in rows if r is not None), 0)
        return np.array([[np.nan] * width if r is None else r for r in rows])

    return RunData(t=t, x_d=x_d, x=x, f=f, f_min=np.asarray(forces[0].f_min), f_max=np.asarray(forces[0].f_max),
                   f_d=optional("distribution", "f_d"), dq_cfc=optional("cfc", "output"),
                   x_ospc=optional("ospc", "output"))


def summarize(run: RunData) -> dict:
    """Pose error (position |r_d - r| and orientation |phi_d - phi|) and cable forces vs limits."""
    dr = np.linalg.norm(run.x_d[:, :3] - run.x[:, :3], axis=1)
    dphi = np.linalg.norm(run.x_d[:, 3:] - run.x[:, 3:], axis=1)
    below = run.f < run.f_min
    above = run.f > run.f_max
    return {
        "duration_s": float(run.t[-1]),
        "samples": int(len(run.t)),
        "position_error_rms_mm": float(1e3 * np.sqrt(np.mean(dr**2))),
        "position_error_max_mm": float(1e3 * dr.max()),
        "orientation_error_rms_deg": float(np.rad2deg(np.sqrt(np.mean(dphi**2)))),
        "orientation_error_max_deg": float(np.rad2deg(dphi.max())),
        "cable_force_min_N": float(run.f.min()),
        "cable_force_max_N": float(run.f.max()),
        "f_min_N": float(run.f_min.min()),
        "f_max_N": float(run.f_max.max()),
        "samples_below_f_min": int(below.any(axis=1).sum()),
        "samples_above_f_max": int(above.any(axis=1).sum()),
    }


def plot_run(run: RunData, out_dir: Path, prefix: str = "", title: str = "") -> list[Path]:
    """PNG plots of pose error, cable forces and (when recorded) controller outputs, 990 px wide.
    ``title`` names the run (robot, controller, plant, bag) under each figure's heading."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []

    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    err = run.x_d - run.x
    for i, name in enumerate("xyz"):
        ax1.plot(run.t, 1e3 * err[:, i], label=f"{name}_d - {name}")
    ax1.set_ylabel("position error [mm]")
    ax1.legend(loc="upper right")
    for i, name in enumerate("abc"):
        ax2.plot(run.t, np.rad2deg(err[:, 3 + i]), label=f"{name}_d - {name}")
    ax2.set_ylabel("orientation error [deg]")
    ax2.set_xlabel("t [s]")
    ax2.legend(loc="upper right")
    fig.suptitle(_heading("Pose error against the ground truth", title), fontsize=10)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}pose_error.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(9, 5))
    for i in range(run.f.shape[1]):
        line, = ax.plot(run.t, run.f[:, i], label=f"f_{i + 1}")
        if run.f_d is not None:
            ax.plot(run.t, run.f_d[:, i], "--", color=line.get_color(), linewidth=0.8)
    ax.axhline(run.f_min.min(), color="k", linestyle=":", label="f_min / f_max")
    ax.axhline(run.f_max.max(), color="k", linestyle=":")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("cable force at the platform [N]")
    if run.f_d is not None:
        ax.plot([], [], "--", color="0.3", linewidth=0.8, label="f_d (desired, dashed)")
    ax.set_title(_heading("True cable forces at the platform", title), fontsize=10)
    ax.legend(loc="upper right", ncol=3, fontsize=8)
    fig.tight_layout()
    paths.append(out_dir / f"{prefix}cable_forces.png")
    fig.savefig(paths[-1], dpi=110)
    plt.close(fig)

    if run.dq_cfc is not None or run.x_ospc is not None:
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
        if run.dq_cfc is not None:
            for i in range(run.dq_cfc.shape[1]):
                axes[0].plot(run.t, 1e3 * run.dq_cfc[:, i], lw=0.9, label=f"cable {i + 1}")
            axes[0].set_ylabel("Δq_CFC [mm]")
            axes[0].set_title("cable force control output Δq_CFC (3.22)", fontsize=9)
            axes[0].legend(loc="upper right", ncol=4, fontsize=7)
        if run.x_ospc is not None:
            for j, name in enumerate("xyz"):
                axes[1].plot(run.t, 1e3 * run.x_ospc[:, j], lw=0.9, label=name)
            axes[1].set_ylabel("x_OSPC position [mm]")
            axes[1].set_title("operational-space position control output x_OSPC (3.16)", fontsize=9)
            axes[1].legend(loc="upper right", ncol=3, fontsize=7)
        axes[1].set_xlabel("t [s]")
        fig.suptitle(_heading("Controller outputs", title), fontsize=10)
        fig.tight_layout()
        paths.append(out_dir / f"{prefix}controllers.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths


def _heading(what: str, title: str) -> str:
    return f"{what}\n{title}" if title else what


def read_bag(bag) -> RunData:
    """The run recorded in a bag (directory or .mcap), aligned as :func:`run_data` does."""
    from cdpr_tools.bag import BagReader

    reader = BagReader(bag)
    wanted = {f"/{topic}" for topic in TOPICS.values()}
    messages: dict[str, list] = {}
    for m in reader.messages([t for t in reader.topics if t in wanted]):
        messages.setdefault(m.topic.lstrip("/"), []).append(m.msg)
    return run_data(messages)
