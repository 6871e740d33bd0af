"""Plot of a contact run for docs/hybrid_force_control.md: the shipped floor_contact_ipanema3.gcode
against a stiff floor in the in-process closed loop (nominal plant = robot file): contact force
(true and estimated), F_d, state of Fig. 5.4 and x_t over time.

    python scripts/plot_hybrid_force_contact.py docs/img/hybrid_force_contact.png
"""
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "control"))
from test_hybrid_force_control import floor_program_run  # noqa: E402

from cdpr_control.control.hybrid_force_control import STATES  # noqa: E402


def main(out: str) -> None:
    r = floor_program_run()
    t = r.t
    states = [s.state for s in r.hpfc]
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(7, 6), gridspec_kw={"height_ratios": [3, 1, 2]})
    ax = axes[0]
    ax.plot(t, r.w_contact[:, 2], label="F (simulator)", lw=1.2)
    ax.plot(t, [s.F for s in r.hpfc], "--", label="F estimated (wrench - weight)", lw=1)
    ax.plot(t, [s.F_d for s in r.hpfc], "k:", label="F_d", lw=1)
    ax.fill_between(t, 490, 510, color="0.85", label="±2 % of 500 N")
    ax.set_ylabel("contact force [N]")
    ax.legend(loc="lower center", fontsize=8)
    axes[1].plot(t, [STATES.index(s) for s in states], drawstyle="steps-post")
    axes[1].set_yticks(range(len(STATES)), STATES)
    axes[1].set_ylabel("state")
    axes[2].plot(t, 1e3 * np.array([s.x_t for s in r.hpfc]), label="x_t")
    axes[2].plot(t, 1e3 * (r.x_d[:, 2] - r.x[:, 2]), label="platform depth below x_d")
    axes[2].set_ylabel("[mm]")
    axes[2].set_xlabel("t [s]")
    axes[2].legend(fontsize=8)
    fig.suptitle("IPAnema 3, floor_contact_ipanema3.gcode: 500 N on 1e6 N/m (approach bounded by k_env, d_env)", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=80)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/img/hybrid_force_contact.png")
