"""`cdpr identify` on simulator bags: friction (3.45), drives (3.10), (5.11), mass, stiffness (2.16).

The bags are recorded on the default, mismatched plant (cdpr_sim.plant): the fits must recover
the plant's parameters, not the robot file's the controller starts from."""
import dataclasses

import numpy as np
import pytest
import yaml

from cdpr_control.model.robot import load_robot
from cdpr_tools import cli
from cdpr_tools.bag import BagReader
from cdpr_sim.simulator import SimConfig, plant_of
from cdpr_tools.identify import drive, experiments, friction, mass, stiffness


def _plant(name):
    """The simulated robot of the identification runs (they use the default plant and plant seed)."""
    return plant_of(load_robot(name), SimConfig()).robot

# friction_bag: the short identification run of conftest.py


def test_recorded_bag_has_the_graph_topics(friction_bag):
    bag = BagReader(friction_bag)
    types = {name: info.type for name, info in bag.topics.items()}
    assert types[experiments.TOPIC_STATE] == "sensor_msgs/msg/JointState"
    assert types[experiments.TOPIC_COMMAND] == "sensor_msgs/msg/JointState"
    assert types[experiments.TOPIC_FORCES] == "cdpr_msgs/msg/CableForces"
    assert types[experiments.TOPIC_SETPOINT] == "cdpr_msgs/msg/OperationalSetpoint"
    # each command is stamped one period before the state it causes (lockstep graph)
    t_c, _ = bag.series(experiments.TOPIC_COMMAND, "position", stamp="header")
    t_s, _ = bag.series(experiments.TOPIC_STATE, "position", stamp="header")
    assert len(t_s) == len(t_c) + 1 and t_s[0] == 0.0
    assert np.allclose(t_s[1:] - t_c, 1e-3)


def test_friction_fit_meets_tolerance_and_writes_parameter_file(identified_friction):
    # `cdpr identify friction BAG -o friction.yaml --plot fit.png`, run once (conftest.py)
    robot = load_robot("ipanema3_mini")
    params = identified_friction.params
    assert identified_friction.code == 0
    assert identified_friction.out.count("cable ") >= robot.m          # a progress line per cable
    assert identified_friction.plot.stat().st_size > 10_000
    doc = yaml.safe_load(params.read_text())
    p = doc["friction_compensation"]["ros__parameters"]
    assert set(p) == {"mu", "sigma", "F_pv"}
    assert all(len(p[k]) == robot.m and all(isinstance(v, float) for v in p[k]) for k in p)
    fr = _plant("ipanema3_mini").friction
    # the plant's values (measured 0.5 %, 1.6 %, 1.4 %), not the robot file's (off by up to 25 %, 24 %, 27 %)
    assert np.max(np.abs(np.array(p["mu"]) / fr.mu - 1.0)) < 0.03
    assert np.max(np.abs(np.array(p["F_pv"]) / fr.F_pv - 1.0)) < 0.05
    assert np.max(np.abs(np.array(p["sigma"]) / fr.sigma - 1.0)) < 0.05
    assert _node_parameters(params) == p                 # the node loads exactly these values


def _node_parameters(params_file) -> dict:
    """mu, sigma, F_pv as the friction_compensation node reads them from the parameter file."""
    import rclpy
    from rclpy.context import Context

    from cdpr_control.nodes.friction_compensation import FrictionCompensationNode

    context = Context()
    rclpy.init(context=context)
    try:
        node = FrictionCompensationNode(context=context, cli_args=[
            "--ros-args", "-p", "robot:=ipanema3_mini", "--params-file", str(params_file)])
        values = {k: list(node.get_parameter(k).value) for k in ("mu", "sigma", "F_pv")}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return values


@pytest.fixture(scope="module")
def friction_data(friction_bag):
    """The friction run's samples as the fit reads them (about 2 s), once for the tests below; a test
    that changes a field does it on its own copy (dataclasses.replace)."""
    return friction.load_data(BagReader(friction_bag), load_robot("ipanema3_mini"))


def test_friction_offset_epsilon_is_identified(friction_data):
    """A calibration offset between sensor and reference shows up as epsilon (3.45), mu unaffected."""
    robot = load_robot("ipanema3_mini")
    plain = friction.fit_cable(robot, friction_data, 4)      # epsilon: the plant's own sensor offset
    # the reference sensor reads 0.3 N low
    fit = friction.fit_cable(robot, dataclasses.replace(friction_data, f_ref=friction_data.f_ref - 0.3), 4)
    assert fit.epsilon - plain.epsilon == pytest.approx(-0.3, abs=0.02)
    assert fit.mu == pytest.approx(_plant("ipanema3_mini").friction.mu[4], rel=0.10)
    assert fit.rms_with < 0.5 * fit.rms_without


def test_friction_model_without_friction_is_the_sensor_line(friction_data):
    """mu = F_pv = 0: Psi_PF reduces to f_w = F_s / (1 - cos beta_1) (3.36)-(3.40), for every column."""
    robot = load_robot("ipanema3_mini")
    data = friction_data
    F = friction.model_forces(robot, data, 2, [[0.0, 1000.0, 0.0], [0.0, 500.0, 0.0]])
    expected = data.F_s[:, 2] / (1.0 - np.cos(robot.sensor.beta_1))
    assert np.allclose(F, expected[:, None], rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def drive_sweeps(tmp_path_factory):
    """robot name -> (the drive sweep of its cable 2 (1.5 s, up to 60 Hz), the fit of the robot's
    drive model to it): made once for test_drive_fit_meets_tolerance and for the lossy-bag test that
    compares its own fit with this one."""
    cache = {}

    def sweep(robot_name, kind):
        if (robot_name, kind) not in cache:
            bag = experiments.record_drive_sweep(tmp_path_factory.mktemp("sweep") / "sweep", robot_name, cable=2,
                                                 duration=1.5, f_end=60.0, seed=2)
            cache[robot_name, kind] = (bag, *drive.identify(BagReader(bag), kind))
        return cache[robot_name, kind]

    return sweep


@pytest.mark.parametrize("robot_name, kind", [("ipanema3", "pt1_deadtime"), ("ipanema3_mini", "second_order")])
def test_drive_fit_meets_tolerance(drive_sweeps, tmp_path, robot_name, kind, capsys):
    bag, data, fit = drive_sweeps(robot_name, kind)
    assert data.cables == [2]
    d = _plant(robot_name).drive
    if kind == "pt1_deadtime":
        assert fit.params["T_1"] == pytest.approx(d.T_1, rel=0.10)
        assert fit.params["T_d"] == pytest.approx(d.T_d, rel=0.10)
    else:
        assert fit.params["T_w"] == pytest.approx(d.T_w, rel=0.10)
        assert fit.params["zeta"] == pytest.approx(d.zeta, rel=0.10)
        assert fit.params["T_d"] == pytest.approx(d.T_d, abs=0.1 * d.T_w)
    png = tmp_path / "drive.png"
    assert cli.main(["identify", "drive", str(bag), "--model", kind, "--plot", str(png)]) == 0
    assert kind in capsys.readouterr().out and png.stat().st_size > 10_000


def test_drive_model_of_the_true_parameters_reproduces_the_encoder(tmp_path):
    """The fit's forward model with the plant's values matches the bag to the encoder resolution."""
    robot = _plant("ipanema3")
    bag = experiments.record_drive_sweep(tmp_path / "sweep", "ipanema3", duration=0.5, seed=2)
    data = drive.load_data(BagReader(bag))
    theta = drive.simulate("pt1_deadtime", {"T_1": robot.drive.T_1, "T_d": robot.drive.T_d}, data)
    resolution = 2 * np.pi * robot.drive.drum_radius / (robot.drive.gear_ratio * 2**20)
    assert np.max(np.abs(theta - data.theta)) <= 0.5 * resolution + 1e-12


def test_recording_is_deterministic(tmp_path):
    a = experiments.record_drive_sweep(tmp_path / "a", "ipanema3_mini", duration=0.3, seed=5)
    b = experiments.record_drive_sweep(tmp_path / "b", "ipanema3_mini", duration=0.3, seed=5)
    for topic, fields in ((experiments.TOPIC_STATE, ("position", "velocity", "effort")),
                          (experiments.TOPIC_FORCES, ("f",))):
        for x, y in zip(BagReader(a).series(topic, *fields, stamp="header"),
                        BagReader(b).series(topic, *fields, stamp="header")):
            assert np.array_equal(x, y)


def test_smooth_moves_and_sweep():
    x = experiments.smooth_moves([[0] * 6, [0.01, 0, 0, 0, 0, 0]], 0.1, pause=0.01, dt=1e-3)
    assert x[0, 0] == 0.0 and x[-1, 0] == pytest.approx(0.01)
    assert np.all(np.diff(x[:, 0]) >= 0.0)
    assert np.max(np.diff(x[:, 0])) / 1e-3 == pytest.approx(0.1 * np.pi / 3, rel=0.02)  # peak pi L / (2 T)
    s = experiments.sweep(2.0, 1.0, 10.0, 1e-3)
    assert len(s) == 2000 and np.max(np.abs(s)) <= 1.0 and s[0] == 0.0


def test_mass_from_circle_run(tmp_path, capsys):
    robot = load_robot("ipanema3_mini")
    bag = experiments.record_circle_run(tmp_path / "circle", "ipanema3_mini", seed=4, r_c=0.1, frequency=1.0,
                                        revolutions=2, ramp=0.6)
    fit = mass.identify(BagReader(bag), robot)
    assert fit.frequency == pytest.approx(1.0, rel=1e-3)
    # 5 %: the plant's force sensors are off by up to 1 % in gain and 0.25 % of the range in offset
    # (the thesis under-estimated a 128 kg load by 5.9 %, section 4.1.3)
    assert fit.m_circle == pytest.approx(robot.platform.mass, rel=0.05)
    assert fit.m_static == pytest.approx(robot.platform.mass, rel=0.05)
    assert cli.main(["identify", "mass", str(bag)]) == 0
    assert "(4.3)" in capsys.readouterr().out


def test_circle_trajectory_has_constant_speed_after_the_ramp():
    x = experiments.circle_trajectory([0] * 6, r_c=0.1, frequency=1.0, revolutions=1.0, ramp=0.5)
    t = np.arange(len(x)) * 1e-3
    mask, frequency, radius = mass.constant_speed_window(t, x)
    assert frequency == pytest.approx(1.0, rel=1e-3) and radius == pytest.approx(0.1, rel=1e-3)
    assert x[0] == pytest.approx(np.zeros(6)) and np.all(x[:, 2:] == 0.0)


def test_stiffness_from_tension_steps(tmp_path, capsys):
    """(2.16) on the mismatched plant: its k0 (not the robot file's), with its geometry errors of
    millimetres (as large as the Mini's elongations), l_0 errors, settlement and slack cables."""
    robot = load_robot("ipanema3_mini")
    c = _plant("ipanema3_mini").cable
    assert abs(robot.cable.k0 / c.k0 - 1.0) > 0.05        # the band below tells the plant from the file
    bag = experiments.record_stiffness_run(tmp_path / "stiffness", "ipanema3_mini", seed=6)
    ref = stiffness.identify(BagReader(bag), robot, use_reference=True)       # exact forces
    assert ref.k0 == pytest.approx(c.k0, rel=0.005)
    assert ref.k1 == pytest.approx(c.k1, rel=0.02) and ref.k2 == pytest.approx(c.k2, rel=0.05)
    fit = stiffness.identify(BagReader(bag), robot)                           # compensated sensor forces
    assert fit.k0 == pytest.approx(c.k0, rel=0.03)        # the sensors' gains are off by up to 1 %
    assert cli.main(["identify", "stiffness", str(bag)]) == 0
    assert "(2.16)" in capsys.readouterr().out


def test_resting_mask():
    t_c = np.arange(10) * 0.1
    theta_d = np.array([[0.0]] * 3 + [[1.0]] * 7)
    mask = stiffness.resting_mask(t_c + 0.1, t_c, theta_d, settle=0.25)
    assert mask.tolist() == [False] * 5 + [True] * 5        # 0.25 s after the change at 0.3 s


def test_resting_mask_with_a_force_control_in_the_loop():
    """A command that creeps (a CFC at rest: well below 1 mm/s) is still at rate 1 mm/s, not at rate 0;
    a tension step (3-8 mm/s on the Mini) moves at either."""
    t_c = np.arange(1000) * 1e-3
    theta_d = 5e-7 * np.arange(1000)[:, None]                  # 0.5 mm/s
    theta_d[600:] += 4e-6 * np.arange(1, 401)[:, None]         # from 0.6 s: 4.5 mm/s
    t = t_c + 1e-3
    assert not stiffness.resting_mask(t, t_c, theta_d, settle=0.2).any()
    mask = stiffness.resting_mask(t, t_c, theta_d, settle=0.2, rate=1e-3)
    assert mask.tolist() == [False] * 199 + [True] * 400 + [False] * 401


def test_after_preload_leaves_out_the_rests_up_to_the_highest_forces():
    mask = np.array([True] * 3 + [False] * 2 + [True] * 3 + [False] + [True] * 2)
    force_sum = np.array([10.0] * 5 + [40.0] * 3 + [30.0] * 3)      # power-on level, pre-load, a step down
    assert stiffness.after_preload(mask, force_sum).tolist() == [False] * 9 + [True] * 2


def test_samples_the_recorder_lost_are_left_out_with_a_warning(friction_bag, friction_data, tmp_path):
    """A recorder in a process of its own on a busy machine loses a message now and then (CI did, in
    the graph's identification test). Every 40th ground-truth pose and every 55th reference force
    dropped from the friction run: the winch state keeps the samples that have both, warns with the
    count, and those samples are the original's."""
    from cdpr_tools.bag.writer import BagWriter
    from cdpr_tools.identify import bag_data

    original, lossy = BagReader(friction_bag), tmp_path / "lossy"
    counts = {experiments.TOPIC_POSE: 0, experiments.TOPIC_FORCES: 0}
    lost = {experiments.TOPIC_POSE: set(), experiments.TOPIC_FORCES: set()}
    with BagWriter(lossy) as writer:
        for message in original.messages():
            if message.topic in counts:
                counts[message.topic] += 1
                every = 40 if message.topic == experiments.TOPIC_POSE else 55
                if counts[message.topic] % every == 0:
                    lost[message.topic].add(message.msg.header.stamp.sec * 10**9 + message.msg.header.stamp.nanosec)
                    continue
            writer.write(message.topic, message.type, message.data, message.log_time_ns,
                         publish_time_ns=message.publish_time_ns)
    robot = load_robot("ipanema3_mini")
    full = friction_data                                  # friction.load_data(original, robot)
    with pytest.warns(UserWarning, match=r"samples of /winch/state have no sample of .* \(the recorder lost them\)"):
        data = friction.load_data(BagReader(lossy), robot)
    ns_full, ns = (np.rint(t * 1e9).astype(np.int64) for t in (full.t, data.t))
    dropped = set(ns_full) - set(ns)
    assert dropped and dropped <= lost[experiments.TOPIC_POSE] | lost[experiments.TOPIC_FORCES]
    assert len(ns) == len(ns_full) - len(dropped)
    keep = np.isin(ns_full, ns)
    for name in ("theta", "thetadot", "F_s", "f_ref"):
        np.testing.assert_array_equal(getattr(data, name), getattr(full, name)[keep], err_msg=name)
    # beta is held until the platform moved 1 mm (wrap_angles): a lost sample can shift a refresh by a
    # period, so the two differ by what 1 mm turns a cable of the Mini (about 1 mrad), no more
    np.testing.assert_allclose(data.beta, full.beta[keep], rtol=0, atol=2e-3)


def test_a_bag_of_two_graphs_is_refused(friction_bag, tmp_path):
    """Two graphs in one ROS domain (two users) interleave their winch states: a clear error, not a fit."""
    from cdpr_tools.bag.writer import BagWriter
    from cdpr_tools.identify import bag_data

    twice, start = tmp_path / "twice", None
    with BagWriter(twice) as writer:
        for message in BagReader(friction_bag).messages():
            start = message.log_time_ns if start is None else start
            if message.log_time_ns > start + 500_000_000:       # the first 0.5 s of the run are enough
                break
            for shift in (0, 1):          # the second graph's messages arrive 1 ns later, stamps alike
                writer.write(message.topic, message.type, message.data, message.log_time_ns + shift)
    with pytest.raises(ValueError, match="go back in time: two graphs published"):
        bag_data.winch_state(BagReader(twice))


def test_drive_fit_of_a_bag_that_lost_commands_and_states(drive_sweeps, tmp_path):
    """The drive fit from a bag whose recorder lost every 40th winch state and every 55th command (as
    a recorder in a process of its own did in CI: "stamps do not match"): a lost command is interpolated
    between its neighbours, a lost state left out of the fit, a warning counts both, and the parameters
    are the lossless bag's within a per cent."""
    from cdpr_tools.bag.writer import BagWriter

    bag, full_data, full = drive_sweeps("ipanema3", "pt1_deadtime")
    original, lossy = BagReader(bag), tmp_path / "lossy"
    every = {experiments.TOPIC_STATE: 40, experiments.TOPIC_COMMAND: 55}
    counts = dict.fromkeys(every, 0)
    with BagWriter(lossy) as writer:
        for message in original.messages():
            if message.topic in counts:
                counts[message.topic] += 1
                if counts[message.topic] % every[message.topic] == 0:
                    continue
            writer.write(message.topic, message.type, message.data, message.log_time_ns,
                         publish_time_ns=message.publish_time_ns)
    with pytest.warns(UserWarning, match=r"the recorder lost \d+ of \d+ /winch/command .* and \d+ of \d+ /winch/state"):
        data, fit = drive.identify(BagReader(lossy), "pt1_deadtime")
    assert data.theta.shape == full_data.theta.shape
    lost = np.isnan(data.theta[:, 0])
    assert lost.sum() >= counts[experiments.TOPIC_STATE] // 40 - 1
    np.testing.assert_array_equal(data.theta[~lost], full_data.theta[~lost])
    for name, value in full.params.items():
        assert fit.params[name] == pytest.approx(value, rel=0.01), name


@pytest.mark.parametrize("command, function", [("load-steps", "run_experiment"), ("load-program", "run_program_experiment")])
def test_the_load_experiments_take_the_load_compensations_model_and_parameters(tmp_path, monkeypatch, command, function):
    """`cdpr identify load-steps` and `load-program` parse and hand on --model and --lc-params alike
    (load-program stopped with "'Namespace' object has no attribute 'model'" before either existed for it)."""
    from cdpr_control.control.load_compensation import LoadCompensationParams
    from cdpr_tools.cli import main
    from cdpr_tools.identify import load_steps

    calls = []
    row = {"ok": True, "outcome": "ok", "sag_mm_per_kg": 0.1, "max_abs_z_error_mm": 1.0,
           "rms_position_error_mm": 1.0, "max_estimate_error_percent": 2.0}
    monkeypatch.setattr(load_steps, function, lambda *args, **kwargs: calls.append(kwargs) or {"ik_lc": row})
    lc = tmp_path / "lc.yaml"
    lc.write_text("load_compensation:\n  ros__parameters:\n    settlement_ratio: 0.3\n    settlement_time: 2.5\n")
    base = ["identify", command, str(tmp_path / "out"), "--configs", "ik_lc"]
    assert main(base) == 0 and calls[-1]["model"] is None and calls[-1]["lc_params"] is None
    assert main(base + ["--model", "ipanema3", "--lc-params", str(lc)]) == 0
    assert calls[-1]["model"] == "ipanema3"
    assert calls[-1]["lc_params"] == LoadCompensationParams(tare_at_start=True, settlement_ratio=0.3, settlement_time=2.5)
