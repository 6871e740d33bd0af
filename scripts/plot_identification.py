"""Figures of the identification walk-through (docs/identify.md): what the identified parameters
improve, measured on the bags the graph recorded.

    python scripts/plot_identification.py FRICTION_BAG STIFFNESS_BAG friction.yaml robot.yaml [--out docs/img]

* ``identify_friction_hysteresis.png``: the force at the platform that the friction compensation
  (3.44) estimates from the winch sensor, minus the reference force F_np, against the winch velocity
  (the hysteresis of the pulley friction), with the robot file's friction parameters and with the
  identified ones (``cdpr identify friction -o friction.yaml``); and its rms per cable. Each
  cable's mean error is removed: the force sensor's offset (epsilon of (3.45), up to 0.14 N here)
  is the sensor calibration's to remove, and no friction parameter changes it.
* ``identify_static_accuracy.png``: at the rests of the tension steps, the elongation (2.17) the
  cable model predicts from the compensated sensor forces minus the measured one (IK{x} - theta of
  the tracker's pose and the encoders, each cable's mean removed: the encoder offset), with the
  robot file (cable and friction) and with the identified ones (``cdpr identify stiffness -o
  robot.yaml``, the friction file): the length error IK-only control would leave at standstill.

Then every ``identify_*.png`` in the folder (also those of ``cdpr identify ... --plot``) is stored
with a palette of 64 colours: the friction fit's 26,000 noisy samples per curve take 340 kB as
full-colour PNG, 110 kB so (CONTRIBUTING.md: images in docs/img under 150 kB), and line plots on
white look the same.
"""
import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402

from cdpr_control.model import cable  # noqa: E402
from cdpr_control.model.kinematics import inverse_kinematics  # noqa: E402
from cdpr_control.model.robot import load_robot  # noqa: E402
from cdpr_tools.bag import BagReader  # noqa: E402
from cdpr_tools.identify import bag_data, friction, stiffness  # noqa: E402
from cdpr_tools.identify.mass import compensated_forces  # noqa: E402

BEFORE, AFTER = ("robot file", "tab:orange"), ("identified", "tab:blue")


def friction_params(path) -> dict:
    return yaml.safe_load(Path(path).read_text())["friction_compensation"]["ros__parameters"]


def hysteresis(bag_path, robot, identified: dict, out: Path) -> None:
    bag = BagReader(bag_path)
    data = friction.load_data(bag, robot)
    fr = robot.friction
    errors = {}
    for i in range(robot.m):
        sets = [[fr.mu[i], fr.sigma[i], fr.F_pv[i]], [identified[k][i] for k in ("mu", "sigma", "F_pv")]]
        e = friction.model_forces(robot, data, i, sets) - data.f_ref[:, i:i + 1]
        errors[i] = e - e.mean(axis=0)          # the sensor's offset is the calibration's, not the friction's
    rms = np.array([np.sqrt(np.mean(e**2, axis=0)) for e in errors.values()])     # (m, 2)
    worst = int(np.argmax(rms[:, 0]))
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.4), width_ratios=(1.4, 1))
    for j, (label, colour) in enumerate((BEFORE, AFTER)):
        a.plot(1e3 * data.thetadot[:, worst], errors[worst][:, j], ".", ms=1.2, color=colour, alpha=0.5,
               label=f"{label}: rms {rms[worst, j]:.3f} N")
        b.bar(np.arange(1, robot.m + 1) + (j - 0.5) * 0.38, rms[:, j], 0.38, color=colour, label=label)
    a.set_xlabel(f"winch {worst + 1} velocity thetadot [mm/s]")
    a.set_ylabel("estimated - reference force, mean removed [N]")
    a.set_title(f"cable {worst + 1} (largest error with the robot file)", fontsize=9)
    a.legend(fontsize=8, markerscale=8)
    b.set_xlabel("cable")
    b.set_ylabel("rms of the force error [N]")
    b.set_title("every cable", fontsize=9)
    b.legend(fontsize=8)
    fig.suptitle(f"Friction compensation (3.44) before and after `cdpr identify friction`: "
                 f"{bag_data.run_title(bag, robot)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "identify_friction_hysteresis.png", dpi=90)
    plt.close(fig)
    print(f"friction force error rms per cable [N], robot file: {np.round(rms[:, 0], 3).tolist()}, "
          f"identified: {np.round(rms[:, 1], 3).tolist()}")


def elongation_errors(bag, model_robot, robot, friction_values) -> tuple[np.ndarray, np.ndarray]:
    """(f, e) at the rests after the pre-load: forces (n, m) and the model's elongation error (n, m)
    [m], each cable's mean removed (the encoder offset)."""
    data = friction.load_data(bag, model_robot)
    t_c, theta_d = bag_data.commands(bag)
    mask = stiffness.after_preload(stiffness.resting_mask(data.t, t_c, theta_d, 0.2, 1e-3), data.F_s.sum(axis=1))
    f = compensated_forces(model_robot, data, float(np.median(np.diff(data.t))), friction_values)[mask]
    x = bag_data.poses(bag, data.t)[mask]
    q = np.array([inverse_kinematics(robot, xk).q for xk in x])        # the tracker's pose, nominal geometry
    measured = q - data.theta[mask]
    predicted = cable.elongation_from_force(model_robot, f, cable.total_free_length(model_robot, q))
    e = predicted - measured
    return f, e - e.mean(axis=0)


def static_accuracy(bag_path, robot, identified_robot, identified_friction: dict, out: Path) -> None:
    bag = BagReader(bag_path)
    fig, ax = plt.subplots(figsize=(9, 4.8))
    summary = []
    for (label, colour), model, values in ((BEFORE, robot, None), (AFTER, identified_robot, identified_friction)):
        f, e = elongation_errors(bag, model, robot, values)
        rms = float(1e6 * np.sqrt(np.mean(e**2)))
        ax.plot(f.ravel(), 1e6 * e.ravel(), ".", ms=1.5, color=colour, alpha=0.5,
                label=f"{label}: rms {rms:.1f} um, max {1e6 * np.abs(e).max():.1f} um")
        summary.append(rms)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel("cable force from the compensated sensor [N]")
    ax.set_ylabel("predicted - measured elongation [um]")
    ax.legend(fontsize=8, markerscale=8)
    ax.set_title(f"Cable length model (2.17) at rest, all cables, before and after `cdpr identify stiffness`:\n"
                 f"{bag_data.run_title(bag, robot)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "identify_static_accuracy.png", dpi=90)
    plt.close(fig)
    print(f"elongation error at rest rms [um], robot file: {summary[0]:.1f}, identified: {summary[1]:.1f}")


def compact(folder: Path) -> None:
    """Store each identify_*.png of ``folder`` with a 64-colour palette (see the module's docstring)."""
    from PIL import Image

    for path in sorted(folder.glob("identify_*.png")):
        with Image.open(path) as image:
            small = image.convert("RGB").quantize(colors=64)
        small.save(path, optimize=True)
        print(f"{path}: {path.stat().st_size // 1024} kB")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("friction_bag")
    p.add_argument("stiffness_bag")
    p.add_argument("friction", help="friction_compensation parameter file of `cdpr identify friction -o`")
    p.add_argument("robot_file", help="robot file of `cdpr identify stiffness -o`")
    p.add_argument("--robot", default="ipanema3_mini", help="the robot file the graph ran with")
    p.add_argument("--out", default="docs/img", help="folder for the PNG files")
    args = p.parse_args(argv)
    robot, out = load_robot(args.robot), Path(args.out)
    identified = friction_params(args.friction)
    hysteresis(args.friction_bag, robot, identified, out)
    static_accuracy(args.stiffness_bag, robot, load_robot(args.robot_file), identified, out)
    compact(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
