"""``cdpr identify``: model parameters from recorded bags (thesis sections 3.3.1, 3.7.2, 4.1.1, 4.3).

    cdpr identify friction BAG [-o params.yaml] [--plot fit.png] [--robot NAME] [--cables 1,2]
    cdpr identify drive BAG [--model pt1_deadtime|second_order] [--robot NAME] [--plot fit.png]
    cdpr identify mass BAG [--robot NAME] [--friction params.yaml] [--reference] [--plot [fit.png]]
    cdpr identify stiffness BAG [--robot NAME] [--friction params.yaml] [--reference] [-o robot.yaml]
    cdpr identify settlement BAG [--robot robot.yaml] [--friction params.yaml] [-o lc_params.yaml]
    cdpr identify eigenfrequency BAG [--robot NAME] [--friction params.yaml] [--reference] [--plot [fit.png]]
    cdpr identify record-experiments OUTDIR [--robot NAME] [--seed N] [--plant P] [--plant-seed N]
    cdpr identify load-steps OUTDIR [--robot NAME] [--configs ik,ik_lc,...] [--step-mass KG] [--steps N] [--plant P]
    cdpr identify load-program OUTDIR [--robot NAME] [--payloads 40,80] [--program NAME]
"""
from __future__ import annotations

import sys


def _force_arguments(parser) -> None:
    """The options of the identifications that need the cable forces at the platform."""
    parser.add_argument("--robot", default="ipanema3_mini", help="robot name or file (geometry, mass, cable, friction)")
    parser.add_argument("--friction", metavar="YAML", help="friction_compensation parameter file (default: robot file)")
    parser.add_argument("--reference", action="store_true", help="use ground_truth/cable_forces instead of F_s")


def add_parser(sub) -> None:
    p = sub.add_parser("identify", help="identify friction, drive, mass, stiffness, eigenfrequency from bags")
    what = p.add_subparsers(dest="what", metavar="WHAT", required=True)

    f = what.add_parser("friction", help="pulley friction mu, sigma, F_pv per cable by LM (3.45)")
    f.add_argument("bag", help="bag with winch/state, ground_truth/cable_forces and ground_truth/pose or setpoint")
    f.add_argument("-o", "--output", help="write the friction_compensation parameter file (YAML)")
    f.add_argument("--plot", metavar="PNG", help="plot of the fit against the reference force")
    f.add_argument("--robot", default="ipanema3_mini", help="robot name or file (pulley geometry)")
    f.add_argument("--cables", help="comma-separated 1-based cables (default: all)")
    f.add_argument("--start", nargs=3, type=float, default=(0.02, 1000.0, 1.0), metavar=("MU", "SIGMA", "F_PV"),
                   help="start values (default 0.02 1000 1.0)")
    f.set_defaults(run=run_friction)

    d = what.add_parser("drive", help="drive dynamics from a sine sweep: (3.10) or (5.11)")
    d.add_argument("bag", help="bag with winch/command and winch/state")
    d.add_argument("--model", choices=("pt1_deadtime", "second_order"),
                   help="model to fit (default: the drive model of the --robot file)")
    d.add_argument("--robot", default="ipanema3_mini", help="robot name or file (its drive model is the default)")
    d.add_argument("--plot", metavar="PNG", nargs="?", const="drive_fit.png",
                   help="plot of the fit (default file drive_fit.png)")
    d.set_defaults(run=run_drive)

    m = what.add_parser("mass", help="platform mass and centre of gravity from the circle run (4.2)-(4.4)")
    m.add_argument("bag", help="bag with winch/state, setpoint and ground_truth/pose")
    _force_arguments(m)
    m.add_argument("--plot", metavar="PNG", nargs="?", const="mass_fit.png",
                   help="plot of the force harmonics (default file mass_fit.png)")
    m.set_defaults(run=run_mass)

    k = what.add_parser("stiffness", help="cable stiffness k0, k1, k2 (2.16) from tension steps at rest")
    k.add_argument("bag", help="bag with winch/state, winch/command and ground_truth/pose or setpoint")
    _force_arguments(k)
    k.add_argument("-o", "--output", metavar="ROBOT_YAML",
                   help="write a copy of the --robot file with the identified k0, k1, k2 and l_0")
    k.set_defaults(run=run_stiffness)

    st = what.add_parser("settlement", help="cable settlement under load (4.1.3) from a payload run with the pose")
    st.add_argument("bag", help="bag with winch/state and ground_truth/pose (record_settlement_run)")
    _force_arguments(st)
    st.add_argument("--rest", type=float, default=0.4, help="s before the payload: the settled reference")
    st.add_argument("-o", "--output", help="write the load_compensation parameter file (YAML)")
    st.set_defaults(run=run_settlement)

    e = what.add_parser("eigenfrequency", help="platform eigenfrequency in z from a knock, against (4.8)")
    e.add_argument("bag", help="bag with winch/state, ground_truth/cable_forces and ground_truth/pose")
    _force_arguments(e)
    e.add_argument("--plot", metavar="PNG", nargs="?", const="eigenfrequency_fit.png",
                   help="plot of the fitted decay (default file eigenfrequency_fit.png)")
    e.set_defaults(run=run_eigenfrequency)

    r = what.add_parser("record-experiments", help="record the identification runs with the simulator")
    r.add_argument("outdir", help="directory for the bags (friction/, drive_sweep/, circle/, stiffness/, pulse/)")
    r.add_argument("--robot", default="ipanema3_mini")
    r.add_argument("--seed", type=int, default=1, help="sensor noise seed (default 1)")
    r.add_argument("--plant", default="mismatched", choices=("mismatched", "nominal"),
                   help="the simulated robot: cdpr_sim.plant (default mismatched)")
    r.add_argument("--plant-seed", type=int, default=1, help="which mismatched robot (default 1)")
    r.set_defaults(run=run_record)

    ls = what.add_parser("load-steps", help="online load identification and compensation (4.4)-(4.6): payload "
                         "steps at standstill in the simulator (section 4.1.3, Fig. 4.6)")
    ls.add_argument("outdir", help="directory for load_compensation_steps.png and .json")
    ls.add_argument("--robot", default="ipanema3")
    ls.add_argument("--configs", default="ik,ik_lc,ospc,force_control,force_control_lc",
                    help="controller configurations (cdpr_tools.identify.load_steps.CONFIGS), comma-separated")
    ls.add_argument("--position", nargs=3, type=float, default=(-1.0, -1.0, 0.5), metavar=("X", "Y", "Z"),
                    help="platform position [m] (default: the thesis' -1 -1 0.5)")
    ls.add_argument("--step-mass", type=float, default=8.0, help="payload step [kg] (default 8)")
    ls.add_argument("--steps", type=int, default=16, help="steps up, then the same down (default 16)")
    ls.add_argument("--dwell", type=float, default=3.0, help="time per step [s] (default 3)")
    ls.add_argument("--plant", default="mismatched", choices=("mismatched", "nominal"),
                    help="the simulated robot: cdpr_sim.plant (default mismatched)")
    _model_arguments(ls)
    ls.set_defaults(run=run_load_steps)

    lp = what.add_parser("load-program", help="a program run with payloads, with and without load "
                         "compensation (section 4.1.3, Fig. 4.7)")
    lp.add_argument("outdir", help="directory for load_compensation_program.png and .json")
    lp.add_argument("--robot", default="ipanema3")
    lp.add_argument("--payloads", default="40,80", help="payloads [kg], comma-separated (default 40,80)")
    lp.add_argument("--program", default="payload_moves_ipanema3", help="shipped program or .gcode file")
    lp.add_argument("--configs", default="ik,ik_lc", help="controller configurations, comma-separated")
    lp.add_argument("--plant", default="mismatched", choices=("mismatched", "nominal"),
                    help="the simulated robot: cdpr_sim.plant (default mismatched)")
    _model_arguments(lp)
    lp.set_defaults(run=run_load_program)


def _model_arguments(p) -> None:
    """The load compensation's model and parameters, for load-steps and load-program alike."""
    p.add_argument("--model", help="robot file of the load compensation's model (e.g. with the identified "
                   "cable stiffness); default: --robot, from which the simulated plant is built")
    p.add_argument("--lc-params", metavar="YAML", help="load_compensation parameter file (e.g. the settlement "
                   "of `cdpr identify settlement -o`) over the defaults")


def run_friction(args) -> int:
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import friction

    from cdpr_tools.identify import bag_data

    robot = load_robot(args.robot)
    cables = None if not args.cables else [int(c) - 1 for c in args.cables.split(",")]
    print(f"fitting (3.45) per cable on {args.bag} ...", flush=True)
    bag = BagReader(args.bag)
    data, fits = friction.identify(bag, robot, cables, tuple(args.start), jit=_jit(),
                                   progress=lambda line: print(line, flush=True))
    if args.output:
        if len(fits) != robot.m:
            raise ValueError(f"a parameter file needs all {robot.m} cables (drop --cables)")
        friction.write_parameter_file(fits, args.output)
        print(f"wrote {args.output}")
    if args.plot:
        friction.plot(data, fits, args.plot, bag_data.run_title(bag, robot))
        print(f"wrote {args.plot}")
    return 0


def run_drive(args) -> int:
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import drive

    from cdpr_control.model.robot import load_robot

    from cdpr_tools.identify import bag_data

    robot = load_robot(args.robot)
    bag = BagReader(args.bag)
    data, fit = drive.identify(bag, args.model or robot.drive.model)
    print(f"{fit.model} from cables {[c + 1 for c in data.cables]}: {drive.describe(fit)}  (rms {fit.rms:.3g} m)")
    if args.plot:
        drive.plot(data, fit, args.plot, bag_data.run_title(bag, robot))
        print(f"wrote {args.plot}")
    return 0


def run_mass(args) -> int:
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import mass

    from cdpr_tools.identify import bag_data

    robot, bag = load_robot(args.robot), BagReader(args.bag)
    fit = mass.identify(bag, robot, _friction_params(args), args.reference)
    print(f"circle {fit.frequency:.3f} Hz, r_c {fit.r_c:.4f} m, window {fit.window[0]:.2f}-{fit.window[1]:.2f} s")
    print(f"m_p from the force harmonics (4.3): {fit.m_circle:.4f} kg")
    print(f"m_p from w_z (4.4):                 {fit.m_static:.4f} kg")
    print("c_mp (platform frame) from the torques (4.3) [mm]: " + " ".join(f"{1e3 * c:.2f}" for c in fit.c_mp))
    if args.plot:
        mass.plot(fit, args.plot, bag_data.run_title(bag, robot))
        print(f"wrote {args.plot}")
    return 0


def run_eigenfrequency(args) -> int:
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import eigenfrequency

    from cdpr_tools.identify import bag_data

    robot, bag = load_robot(args.robot), BagReader(args.bag)
    fit = eigenfrequency.identify(bag, robot, _friction_params(args), args.reference)
    print(f"z decay {fit.window[0]:.3f}-{fit.window[1]:.3f} s, amplitude {1e3 * fit.amplitude:.3f} mm, "
          f"rms {1e6 * fit.rms:.2f} um")
    print(f"measured: f_d {fit.f_d:.3f} Hz, zeta {fit.zeta:.3f}, undamped f_n {fit.f_n:.3f} Hz")
    print(f"model (4.8): {fit.f_model:.3f} Hz  (f_n {100 * (fit.f_n / fit.f_model - 1):+.2f} %); coupled modes "
          + " ".join(f"{f:.2f}" for f in fit.f_modes) + " Hz")
    if args.plot:
        eigenfrequency.plot(fit, args.plot, bag_data.run_title(bag, robot))
        print(f"wrote {args.plot}")
    return 0


def run_stiffness(args) -> int:
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import stiffness

    fit = stiffness.identify(BagReader(args.bag), load_robot(args.robot), _friction_params(args), args.reference)
    print(f"k0 = {fit.k0:.6g} N, k1 = {fit.k1:.6g}, k2 = {fit.k2:.6g} 1/N  (2.16), "
          f"{fit.n_samples} samples at rest, rms {fit.rms:.3g} m")
    print("encoder offsets delta [mm]: " + " ".join(f"{1e3 * d:.4f}" for d in fit.delta))
    print("free-length corrections g [%]: " + " ".join(f"{1e2 * g:.3f}" for g in fit.g))
    if args.output:
        print(f"wrote {stiffness.write_robot_file(args.robot, fit, args.output)}")
    return 0


def run_settlement(args) -> int:
    from cdpr_control.model.robot import load_robot
    from cdpr_tools.bag import BagReader
    from cdpr_tools.identify import settlement

    fit = settlement.identify(BagReader(args.bag), load_robot(args.robot), _friction_params(args), args.rest)
    print(f"settlement_ratio = {fit.ratio:.4g}, settlement_time = {fit.T:.3g} s  ({fit.n_samples} samples, "
          f"rms {1e3 * fit.rms:.3f} mm)")
    print("lasting growth at the end [mm]: " + " ".join(f"{1e3 * s:.3f}" for s in fit.s_final))
    if args.output:
        import yaml

        with open(args.output, "w") as f:
            yaml.safe_dump({"load_compensation": {"ros__parameters": {
                "settlement_ratio": float(fit.ratio), "settlement_time": float(fit.T),
                "settlement_identified": True}}}, f, sort_keys=False)
        print(f"wrote {args.output}")
    return 0


def _friction_params(args) -> dict | None:
    """mu, sigma, F_pv of a friction_compensation parameter file (--friction), None: robot file."""
    if not args.friction:
        return None
    import yaml

    with open(args.friction) as f:
        return yaml.safe_load(f)["friction_compensation"]["ros__parameters"]


def run_record(args) -> int:
    from cdpr_tools.identify.experiments import record_experiments

    record_experiments(args.outdir, args.robot, args.seed, progress=lambda line: print(line, flush=True),
                       plant=args.plant, plant_seed=args.plant_seed)
    return 0


def _lc_params(path):
    """LoadCompensationParams (tared at the start, as the experiments run) with a load_compensation
    parameter file's entries; None without a file."""
    if not path:
        return None
    import yaml

    from cdpr_control.control.load_compensation import LoadCompensationParams

    with open(path) as f:
        values = yaml.safe_load(f)["load_compensation"]["ros__parameters"]
    return LoadCompensationParams(**{"tare_at_start": True, **values})


def run_load_steps(args) -> int:
    from cdpr_tools.identify.load_steps import CONFIGS, run_experiment

    configs = [c for c in args.configs.split(",") if c]
    unknown = set(configs) - set(CONFIGS)
    if unknown:
        raise SystemExit(f"unknown configurations {sorted(unknown)}; known: {', '.join(CONFIGS)}")
    summary = run_experiment(args.outdir, args.robot, configs, position=tuple(args.position),
                             step_mass=args.step_mass, steps=args.steps, dwell=args.dwell,
                             progress=lambda line: print(line, flush=True), plant=args.plant, model=args.model,
                             lc_params=_lc_params(args.lc_params))
    for name, s in summary.items():
        print(f"{name:18s} sag {s['sag_mm_per_kg']:6.3f} mm/kg  worst static z error {s['max_abs_z_error_mm']:6.1f} mm")
    return _outcome(summary)


def _outcome(summary: dict) -> int:
    """1 (with a line per run on stderr) when a run diverged or was held by the force watch: its
    figures are not the controller's (cdpr_tools.identify.load_steps.run_outcome)."""
    bad = {name: s["outcome"] for name, s in summary.items() if not s["ok"]}
    for name, outcome in bad.items():
        print(f"cdpr identify: {name}: {outcome}", file=sys.stderr)
    return 1 if bad else 0


def run_load_program(args) -> int:
    from cdpr_tools.identify.load_steps import CONFIGS, run_program_experiment

    configs = [c for c in args.configs.split(",") if c]
    unknown = set(configs) - set(CONFIGS)
    if unknown:
        raise SystemExit(f"unknown configurations {sorted(unknown)}; known: {', '.join(CONFIGS)}")
    payloads = [float(m) for m in args.payloads.split(",") if m]
    summary = run_program_experiment(args.outdir, args.robot, configs, payloads, args.program,
                                     progress=lambda line: print(line, flush=True), plant=args.plant, model=args.model,
                                     lc_params=_lc_params(args.lc_params))
    for key, s in summary.items():
        print(f"{key:24s} rms position error {s['rms_position_error_mm']:6.2f} mm  "
              f"estimate error {s['max_estimate_error_percent']:5.1f} %")
    return _outcome(summary)


def _jit():
    """The simulator's compiled kernels when cdpr_sim is there (a robot PC may not have it)."""
    try:
        from cdpr_sim.simulator import compiled
    except ImportError:
        return None
    return compiled
