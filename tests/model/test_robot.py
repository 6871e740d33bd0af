"""Robot descriptions: both shipped files load; broken files fail naming file and key."""
import numpy as np
import pytest
import yaml

from cdpr_control.model.robot import RobotFileError, available_robots, load_robot, robot_path


@pytest.mark.parametrize("name", ["ipanema3", "ipanema3_mini"])
def test_shipped_robot_loads_with_consistent_shapes(name):
    robot = load_robot(name)
    assert robot.m == 8 and robot.n == 6
    assert robot.a.shape == robot.b.shape == robot.pulley_orientation.shape == (8, 3)
    assert robot.r_p.shape == robot.l_0.shape == robot.cable.f_min.shape == (8,)
    assert np.all(robot.cable.f_min < robot.cable.f_max)
    assert np.all(robot.r_p > 0) and robot.platform.mass > 0
    with pytest.raises(ValueError):
        robot.a[0, 0] = 1.0  # arrays are read-only


def test_available_robots_lists_both():
    assert {"ipanema3", "ipanema3_mini"} <= set(available_robots())


def test_thesis_values_ipanema3():
    robot = load_robot("ipanema3")
    np.testing.assert_allclose(robot.a[0], [8.185, 5.693, 3.203])        # table 2.3
    np.testing.assert_allclose(robot.b[7], [-0.086, 0.749, 0.262])       # table 2.3
    np.testing.assert_allclose(robot.pulley_orientation[5], np.deg2rad([-90, 180, 0]))
    assert robot.r_p[0] == pytest.approx(0.052) and robot.r_p[4] == pytest.approx(0.035)
    # assumed k1, k2 reproduce 75 mm at 3000 N over 19.5 m (section 2.1.3) through (2.17)
    c = robot.cable
    k_spec = c.k0 + c.k1 * 3000.0 + c.k2 * 3000.0**2
    assert 3000.0 * 19.5 / k_spec == pytest.approx(0.075, rel=1e-9)
    assert robot.drive.model == "pt1_deadtime" and robot.drive.T_1 == pytest.approx(0.000745)


def test_thesis_values_mini():
    robot = load_robot("ipanema3_mini")
    np.testing.assert_allclose(robot.a[4], [0.531, -0.344, -0.447])     # table 2.4
    np.testing.assert_allclose(robot.friction.mu, [0.016, 0.011, 0.014, 0.017, 0.024, 0.023, 0.024, 0.025])
    assert robot.friction.sigma[3] == pytest.approx(602.0)               # table 3.4, N/m
    assert robot.drive.model == "second_order"
    assert robot.drive.T_w == pytest.approx(0.0139) and robot.drive.zeta == pytest.approx(0.587)
    assert robot.sensor.beta_1 == pytest.approx(np.pi)


def _broken(tmp_path, edit):
    data = yaml.safe_load(robot_path("ipanema3_mini").read_text())
    edit(data)
    path = tmp_path / "broken.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    "edit, key, reason",
    [
        (lambda d: d["geometry"].pop("r_p"), "geometry.r_p", "missing key"),
        (lambda d: d["geometry"].__setitem__("a", [[0.0, 0.0, 0.0]] * 7), "geometry.a", "expected shape (8, 3)"),
        (lambda d: d["geometry"].__setitem__("r_p", [0.01] * 3 + [-0.01] + [0.01] * 4), "geometry.r_p[3]", "> 0"),
        (lambda d: d["platform"].__setitem__("mass", "heavy"), "platform.mass", "expected a number"),
        (lambda d: d["drive"].__setitem__("model", "pt2"), "drive.model", "expected one of"),
        (lambda d: d["cable"].__setitem__("f_min", 50.0), "cable.f_min", "below cable.f_max"),
        (lambda d: d["platform"].__setitem__("inertia", [[1, 0, 0], [0, -1, 0], [0, 0, 1]]), "platform.inertia", "positive definite"),
        (lambda d: d.pop("cable"), "cable.", "missing key"),
        (lambda d: d["friction"].__setitem__("sigma", float("nan")), "friction.sigma", "finite"),
        # accepted before: a typo, a boolean taken for 1.0 m, a doubled anchor, a degenerate platform
        (lambda d: d["cable"].__setitem__("f_mx", 40.0), "cable.f_mx", "unknown key; known here: diameter, f_max"),
        (lambda d: d.__setitem__("gravty", [0, 0, -9.81]), "gravty", "unknown key"),
        (lambda d: d["geometry"].__setitem__("r_p", True), "geometry.r_p", "expected numbers"),
        (lambda d: d["geometry"]["a"].__setitem__(5, list(d["geometry"]["a"][2])), "geometry.a[5]",
         "same anchor point as geometry.a[2]"),
        (lambda d: d["geometry"].__setitem__("b", [[0.0, 0.0, 0.0]] * 8), "geometry.b", "rank 3 < 6"),
    ],
)
def test_broken_file_names_file_and_key(tmp_path, edit, key, reason):
    path = _broken(tmp_path, edit)
    with pytest.raises(RobotFileError) as err:
        load_robot(path)
    message = str(err.value)
    assert str(path) in message and key in message and reason in message


def test_yaml_alias_bomb_is_refused_with_a_short_message(tmp_path):
    lines = ["a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 9)]
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(robot_path("ipanema3_mini").read_text() + "\n".join(lines) + "\n")
    assert bomb.stat().st_size < 20_000
    with pytest.raises(RobotFileError) as err:
        load_robot(bomb)
    assert "more than 100000 values" in str(err.value) and len(str(err.value)) < 300


def test_long_bad_value_is_cut_in_the_message(tmp_path):
    path = _broken(tmp_path, lambda d: d["platform"].__setitem__("mass", ["x"] * 10_000))
    with pytest.raises(RobotFileError, match="characters") as err:
        load_robot(path)
    assert len(str(err.value)) < 300


def test_unknown_robot_lists_shipped_ones():
    with pytest.raises(RobotFileError, match="ipanema3_mini"):
        load_robot("ipanema9")


def test_not_yaml_and_not_mapping(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("geometry: [unclosed")
    with pytest.raises(RobotFileError, match="not valid YAML"):
        load_robot(bad)
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(RobotFileError, match="mapping"):
        load_robot(bad)


def test_payload_parallel_axis():
    robot = load_robot("ipanema3_mini")
    loaded = robot.with_payload(2.0, (0.0, 0.0, 0.1))
    p = loaded.platform
    assert p.mass == pytest.approx(3.0)
    np.testing.assert_allclose(p.center_of_gravity, [0, 0, 0.2 / 3])
    # inertia about the common centre: platform (1 kg at -1/15 m) + point mass (2 kg at +1/30 m)
    expected_xx = robot.platform.inertia[0, 0] + 1.0 * (0.2 / 3) ** 2 + 2.0 * (0.1 - 0.2 / 3) ** 2
    assert p.inertia[0, 0] == pytest.approx(expected_xx)
    assert p.inertia[2, 2] == pytest.approx(robot.platform.inertia[2, 2])
    with pytest.raises(ValueError):
        robot.with_payload(-1.0)
