"""A hand-guiding run like the thesis' Fig. 5.15 (w_x, r_x and the zone over time), in simulation.

    python -m cdpr_tools.admittance_figure docs/img/admittance_guiding.png

The IPAnema 3 Mini with its shipped parameter file, the in-process hand-guiding runner
(:func:`cdpr_sim.hand_guiding.guiding_run`), and the simulated hand pushing: light pulses in
zone 1, a push out of it, a constant push into the wall, release, and back to the origin. Plant: the simulator's defaults for the robot file.
"""
from __future__ import annotations

import sys

import numpy as np

from cdpr_control.control.admittance import AdmittanceController, settings_from
from cdpr_control.control.loop import ControlLoopParams
from cdpr_control.control.force_setpoint import ForceSetpointParams
from cdpr_control.model.robot import load_robot
from cdpr_sim.closed_loop import ClosedLoopRun, HandGuiding, run
from cdpr_sim.hand import Hand, Segment
from cdpr_sim.hand_guiding import GuidingRun, guiding_run

# the push sequence of the figure (and of tests/control/test_admittance_closed_loop.py)
PUSHES = (Segment(0.2, (2.6, 0, 0, 0, 0, 0), "rectangle", 0.5), Segment(1.2, (-2.0, 0, 0, 0, 0, 0), "rectangle", 0.3),
          Segment(2.0, (13.0, 0, 0, 0, 0, 0), "half_sine", 0.5), Segment(3.0, (4.0, 0, 0, 0, 0, 0), "step"),
          Segment(5.0, release=True), Segment(6.0, (-4.5, 0, 0, 0, 0, 0), "rectangle", 1.0))


def plot(g: GuidingRun, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r, outs = g.run, g.source.outputs
    t = r.t
    zones = g.source.controller.zones
    w_adm = np.array([o.w_user[0] for o in outs])
    zone = np.array([o.zone + 1 for o in outs])
    fig, ax = plt.subplots(3, 1, figsize=(7.0, 5.2), sharex=True, gridspec_kw={"height_ratios": [2, 2, 1]})
    ax[0].plot(t, g.hand.wrench(t - 1e-3)[:, 0], color="0.6", lw=1.0, label="hand (applied)")
    ax[0].plot(t[1:], w_adm, lw=1.0, label=r"$w_{Adm,x}$ (5.9)")
    ax[0].set_ylabel(r"$w_x$ [N]")
    ax[1].plot(t, 1e3 * r.x_d[:, 0], lw=1.0, label=r"$r_{d,x}$ (set-point)")
    ax[1].plot(t, 1e3 * r.x[:, 0], "--", lw=1.0, label=r"$r_x$ (ground truth)")
    for y in (zones.zones[0].size, zones.box[0]):
        ax[1].axhline(1e3 * y, color="0.75", lw=0.8)
    ax[1].set_ylabel(r"$r_x$ [mm]")
    ax[2].step(t[1:], zone, where="post", lw=1.0)
    ax[2].set_yticks([1, 2, 3])
    ax[2].set_ylabel("zone")
    ax[2].set_xlabel("t [s]")
    for a in ax[:2]:
        a.legend(loc="upper right", fontsize=8)
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle("Hand guiding, IPAnema 3 Mini (simulation)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = argv[0] if argv else "admittance_guiding.png"
    plot(guiding_run(PUSHES, 8.5), path)
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
