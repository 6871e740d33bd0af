"""Figures a reader can read (issue 27, item 7): the identification and analysis plots name robot,
controller and bag in their title, label every axis with its unit, give a legend where several
curves share an axis (eight Δq_CFC, three OSPC outputs, the loops of the Nyquist diagram) and fit a
screen. Each figure is drawn from small synthetic data; the drawn Figure is inspected as saved."""
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

from cdpr_control.analysis import stability  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from cdpr_tools import run_report  # noqa: E402
from cdpr_tools.identify import drive, eigenfrequency, friction, mass  # noqa: E402

TITLE = "IPAnema 3 Mini, force_control, bag run1"
SCREEN = (1280, 900)  # px a figure must fit into


@pytest.fixture
def saved(monkeypatch):
    """The figures as they are saved: (figure, dpi) per savefig call."""
    figures = []
    original = Figure.savefig

    def record(fig, path, *args, **kwargs):
        figures.append((fig, kwargs.get("dpi", fig.dpi)))
        return original(fig, path, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return figures


def heading(fig) -> str:
    texts = [fig._suptitle.get_text()] if fig._suptitle else []
    return " ".join(texts + [ax.get_title() for ax in fig.axes])


def legend_labels(fig, ax=None) -> list[str]:
    """The labels of ``ax``'s legend and the figure's (``ax`` None: of every legend in the figure)."""
    axes = fig.axes if ax is None else [ax]
    legends = [a.get_legend() for a in axes if a.get_legend()] + fig.legends
    return [t.get_text() for legend in legends for t in legend.get_texts()]


def check_readable(fig, dpi) -> None:
    """Fits the screen; every visible axis has a y label, and every label has a unit; where an axis
    has several curves, each labelled curve is in a legend of the figure."""
    width, height = fig.get_size_inches() * dpi
    assert width <= SCREEN[0] and height <= SCREEN[1], (width, height)
    in_legends = set(legend_labels(fig))
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        assert ax.get_ylabel(), f"an axis without a y label: {ax.get_title()!r}"
        for label in (ax.get_xlabel(), ax.get_ylabel()):
            if label:
                assert "[" in label and "]" in label, f"no unit in axis label {label!r}"
        curves = [line for line in ax.get_lines() if len(line.get_xdata()) > 2]
        if len(curves) > 1:
            labels = [line.get_label() for line in curves if not line.get_label().startswith("_")]
            assert labels and set(labels) <= in_legends, f"curves without a legend: {ax.get_title()!r}"


def test_friction_fit(saved, tmp_path):
    n, m = 200, 8
    t = np.arange(n) * 1e-3
    data = friction.FrictionData(t, np.zeros((n, m)), np.zeros((n, m)), np.full((n, m), 10.0),
                                 np.full((n, m), 10.5), np.zeros((n, m)))
    fits = [friction.FrictionFit(i, 0.02, 1000.0, 1.5, 0.1, 0.5, 0.03, 10, np.full(n, 10.4), np.full(n, 10.1))
            for i in range(m)]
    friction.plot(data, fits, tmp_path / "fit.png", TITLE)
    (fig, dpi), = saved
    check_readable(fig, dpi)
    assert TITLE in heading(fig)
    labels = legend_labels(fig, fig.axes[0])
    assert any("reference" in label for label in labels) and any("model" in label for label in labels)
    # the reference is drawn wider than the model over it, so it stays visible where they agree
    reference = next(line for line in fig.axes[0].get_lines() if "reference" in line.get_label())
    model = next(line for line in fig.axes[0].get_lines() if "model" in line.get_label())
    assert reference.get_linewidth() > 2 * model.get_linewidth() and model.get_zorder() >= reference.get_zorder()


def test_drive_fit(saved, tmp_path):
    k = 100
    t = np.arange(k + 1) * 1e-3
    data = drive.DriveData(t, np.zeros((k, 1)), np.zeros((k + 1, 1)), [2], 1e-3)
    fit = drive.DriveFit("second_order", {"T_w": 0.0148, "zeta": 0.536, "T_d": 0.0007}, 1e-7, 5, np.zeros((k + 1, 1)))
    drive.plot(data, fit, tmp_path / "drive.png", TITLE)
    (fig, dpi), = saved
    check_readable(fig, dpi)
    assert TITLE in heading(fig) and "winch 3" in heading(fig)
    assert any("T_w = 0.0148 s" in label for label in legend_labels(fig, fig.axes[0]))


def test_eigenfrequency_fit(saved, tmp_path):
    t = np.arange(100) * 1e-3
    fit = eigenfrequency.EigenFit(30.0, 0.2, 30.6, 30.5, np.array([30.5]), 1e-3, (0.2, 0.3), 1e-6, t,
                                  np.zeros(100), np.zeros(100))
    eigenfrequency.plot(fit, tmp_path / "eigen.png", TITLE)
    (fig, dpi), = saved
    check_readable(fig, dpi)
    assert TITLE in heading(fig)


def test_stability_has_a_nyquist_legend_and_fits_a_screen(saved, tmp_path):
    robot = load_robot("ipanema3_mini")
    cfc, _, dt = stability.controller_params(robot)
    loops = {"CFC": stability.cfc_open_loop(robot, cfc, 1.0, dt), "CFC, kappa 0.5": stability.cfc_open_loop(robot, cfc, 0.5, dt)}
    stability.plot(robot, loops, tmp_path / "stability.png", "CFC K_p 0.85")
    (fig, dpi), = saved
    check_readable(fig, dpi)
    width, height = fig.get_size_inches() * dpi
    assert height >= 0.5 * width, "a strip of 1000 x 290 px is too flat to read"
    nyquist = next(ax for ax in fig.axes if ax.get_title() == "Nyquist")
    labels = legend_labels(fig, nyquist)
    assert sum(label.startswith("CFC") and "GM" in label for label in labels) == 2
    assert robot.name in heading(fig) and "CFC K_p 0.85" in heading(fig)


def test_controllers_png_has_legends_and_names_the_run(saved, tmp_path):
    n, m = 50, 8
    t = np.arange(n) * 1e-3
    run = run_report.RunData(t=t, x_d=np.zeros((n, 6)), x=np.zeros((n, 6)), f=np.full((n, m), 10.0),
                             f_min=np.full(m, 5.0), f_max=np.full(m, 40.0), f_d=np.full((n, m), 10.0),
                             dq_cfc=np.zeros((n, m)), x_ospc=np.zeros((n, 6)))
    paths = run_report.plot_run(run, tmp_path, "run1_", TITLE)
    assert [Path(p).name for p in paths] == ["run1_pose_error.png", "run1_cable_forces.png", "run1_controllers.png"]
    for fig, dpi in saved:
        check_readable(fig, dpi)
        assert TITLE in heading(fig)
    controllers = saved[-1][0]
    cfc, ospc = controllers.axes
    assert len(legend_labels(controllers, cfc)) == m and legend_labels(controllers, ospc) == ["x", "y", "z"]


def test_mass_fit(saved, tmp_path):
    t = np.arange(200) * 1e-3
    w = np.column_stack([np.cos(np.pi * t), np.sin(np.pi * t)])
    fit = mass.MassFit(1.0, 0.98, 0.5, 0.1, (0.0, 0.2), np.zeros(3), t, w, w)
    mass.plot(fit, tmp_path / "mass.png", TITLE)
    (fig, dpi), = saved
    check_readable(fig, dpi)
    assert TITLE in heading(fig) and "m_p 1.0000 kg" in heading(fig)


def test_cdpr_plot_names_robot_controller_and_bag(saved, tmp_path):
    """``cdpr plot BAG --robot``: the run's figures from a bag, titled with what the bag says."""
    from cdpr_tools import cli
    from cdpr_tools.identify import experiments

    bag = experiments.record_friction_run(tmp_path / "run1", amplitudes=(0.001,), pause=0.05, fast_velocities=())
    assert cli.main(["plot", str(bag), "-o", str(tmp_path / "png"), "--robot", "ipanema3_mini"]) == 0
    assert sorted(p.name for p in (tmp_path / "png").glob("*.png")) == ["run1_cable_forces.png", "run1_pose_error.png"]
    for fig, dpi in saved:
        check_readable(fig, dpi)
        assert "IPAnema 3 Mini, ik_only, bag run1" in heading(fig)
