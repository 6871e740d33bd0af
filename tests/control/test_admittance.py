"""Admittance control library, thesis 5.2: virtual system (5.4)-(5.8) exactly discretised,
eigenfrequency (5.12), zones of section 5.2.1 (Fig. 5.12), user wrench (5.9), limits, switching."""
import numpy as np
import pytest

from cdpr_control.control.admittance import (AdmittanceController, AdmittanceParams, UserWrench,
    UserWrenchParams, VirtualSystem, damped_eigenfrequency, default_parameters, exact_step_matrices,
    settings_from)
from cdpr_control.control.admittance_zones import (Zone, ZoneSet, box_from_workspace, check_in_workspace,
    force_limits, hard_box, max_penetration, thesis_zones)
from cdpr_control.model.dynamics import dynamic_wrench, gravity_wrench
from cdpr_control.model.kinematics import twist_from_pose_rates
from cdpr_control.model.robot import load_robot

DT = 1e-3
MINI = load_robot("ipanema3_mini")
TABLE_5_3 = [(31.9, 5.0, 20.0, 0.2), (197.5, 5.0, 20.0, 0.5), (395.4, 5.0, 10.0, 1.0), (9870.2, 5.0, 10.0, 5.0)]


@pytest.mark.parametrize("c, d, m, f_theo", TABLE_5_3)
def test_eigenfrequency_of_table_5_3_from_5_12(c, d, m, f_theo):
    """(5.12) reproduces the theoretical column of table 5.3 (printed to one digit)."""
    assert damped_eigenfrequency(c, d, m) == pytest.approx(f_theo, abs=0.005)


def test_an_overdamped_system_has_no_eigenfrequency():
    with pytest.raises(ValueError, match="underdamped"):
        damped_eigenfrequency(100.0, 2 * np.sqrt(100.0 * 2.0), 2.0)


@pytest.mark.parametrize("c, d, m, f_theo", TABLE_5_3)
def test_exact_discretisation_has_the_continuous_eigenfrequency(c, d, m, f_theo):
    """Discrete poles are exp(s T): their angle / T is omega_d of (5.12) to rounding."""
    Phi, _ = exact_step_matrices(c, d, m, DT)
    z = np.linalg.eigvals(Phi)
    omega = np.abs(np.angle(z[0])) / DT
    sigma = -np.log(np.abs(z[0])) / DT
    assert omega / (2 * np.pi) == pytest.approx(damped_eigenfrequency(c, d, m), rel=1e-9)
    assert sigma == pytest.approx(d / (2 * m), rel=1e-9)


def test_exact_step_matches_the_closed_form_step_response():
    """m e'' + d e' + c e = w from rest: e(t) = w/c (1 - e^{-s t}(cos wt + s/w sin wt))."""
    c, d, m, w = 395.4, 5.0, 10.0, 3.0
    Phi, Gamma = exact_step_matrices(c, d, m, DT)
    z = np.zeros(2)
    s, om = d / (2 * m), 2 * np.pi * damped_eigenfrequency(c, d, m)
    for k in range(1, 2001):
        z = Phi @ z + Gamma * w
        t = k * DT
        if k % 250 == 0:
            e = w / c * (1 - np.exp(-s * t) * (np.cos(om * t) + s / om * np.sin(om * t)))
            assert z[0] == pytest.approx(e, abs=1e-12)


def _virtual(zones=None, v_max=10.0, a_max=100.0, box=None):
    return VirtualSystem(zones or thesis_zones(), DT, v_max, a_max, box)


def _drive(system, w_of_t, T):
    xs = []
    for k in range(int(round(T / DT))):
        xs.append(system.step(w_of_t(k * DT)).copy())
    return np.array(xs)


def test_zone_1_holds_against_the_spring_and_returns_fig_5_12_pulse_1():
    """2.6 N in x for 1 s: equilibrium at 2.6 mm (c = 1000 N/m), back to the origin when released."""
    s = _virtual()
    x = _drive(s, lambda t: np.r_[2.6 if t < 1.0 else 0.0, np.zeros(5)], 2.0)
    assert x[999, 0] == pytest.approx(0.0026, abs=2e-5)
    assert abs(x[-1, 0]) < 1e-4 and s.zone == 0


def test_fig_5_12_sequence_rest_free_wall_and_back():
    """Pulses 2-5 of Fig. 5.12: leave zone 1 and stay, move damped in zone 2, stopped at the wall
    and pushed back to the border at 0.03 m, caught by zone 1 on the way back."""
    s = _virtual()

    def w(t):
        f = 10.2 if 0.0 <= t < 0.27 else 1.5 if 0.6 <= t < 0.95 else 3.0 if 1.5 <= t < 3.0 else \
            -4.0 if 4.0 <= t < 5.0 else 0.0
        return np.r_[f, np.zeros(5)]

    x = _drive(s, w, 7.0)
    t = np.arange(1, len(x) + 1) * DT
    zone = np.array([thesis_zones().index(xi) for xi in x])
    window = (t > 0.4) & (t < 0.6)
    assert np.all(zone[window] == 1)                                # pulse 2 left zone 1 ...
    assert np.ptp(x[window, 0]) < 1e-5                              # ... and stays (damping only)
    assert x[int(1.4 / DT), 0] > x[int(0.59 / DT), 0] + 2e-3        # pulse 3 moved it on, damped
    assert zone[(t > 1.5) & (t < 3.0)].max() == 2                   # pulse 4 reaches the wall zone
    assert x[int(2.9 / DT), 0] == pytest.approx(0.03 + 3.0 / 1000, abs=1e-4)  # held w / c into the wall
    assert x[int(3.99 / DT), 0] == pytest.approx(0.03, abs=2e-5)    # released: back at the border
    assert abs(x[-1, 0]) < 1e-4 and zone[-1] == 0                   # pulse 5: caught by zone 1


def test_border_spring_is_normal_to_the_faces_and_zero_inside():
    z = thesis_zones()
    x = np.array([0.04, 0.01, -0.035, 0.0, 0.06, 0.0])
    i = z.index(x)
    c, target = z.spring(i, x)
    assert z.zones[i].name == "wall"
    np.testing.assert_allclose(target, [0.03, 0.01, -0.03, 0.0, 0.05, 0.0])
    assert c[1] == 0 and c[3] == 0 and c[0] == 1000.0 and c[4] == 50.0


def test_velocity_and_acceleration_limits_hold_and_the_hard_box_is_never_left():
    z = thesis_zones()
    box = hard_box(z, 20.0, 0.25)
    s = _virtual(z, v_max=0.25, a_max=2.0, box=box)
    x, v = [], []
    for k in range(3000):
        s.step(np.r_[20.0, -20.0, 20.0, 0.5, 0.0, 0.0])
        x.append(s.x.copy())
        v.append(s.v.copy())
    x, v = np.array(x), np.array(v)
    assert np.all(np.abs(v[:, :3]) <= 0.25 + 1e-12)
    assert np.all(np.abs(np.diff(v, axis=0)[:, :3]) <= 2.0 * DT + 1e-12)
    assert np.all(x >= box[0] - 1e-12) and np.all(x <= box[1] + 1e-12)
    # with the bounded wrench and velocity, the wall alone stops it within max_penetration
    reach = z.box + max_penetration(z, [20.0, 0.5], [0.25, 0.5])
    assert np.all(np.abs(x[:, :3]) <= reach[:3])


def test_user_wrench_removes_weight_payload_and_inertia():
    robot = MINI.with_payload(0.3, (0.0, 0.0, -0.02))
    uw = UserWrench(robot, DT, UserWrenchParams(T_filter=0.0, dead_band=[0.0, 0.0], w_max=[100.0, 10.0]))
    x = np.array([0.01, -0.02, 0.03, 0.02, -0.01, 0.03])
    xd, xdd = np.array([0.1, 0.0, -0.1, 0.2, 0.0, 0.1]), np.array([1.0, -2.0, 0.5, 3.0, -1.0, 2.0])
    twist, accel = twist_from_pose_rates(x, xd, xdd)
    user = np.array([3.0, -1.0, 2.0, 0.1, 0.0, -0.2])
    w = gravity_wrench(robot, x) + user - dynamic_wrench(robot, x, twist, accel)   # (2.10), (2.33)
    np.testing.assert_allclose(uw.raw(w, x, twist, accel), user, atol=1e-12)
    uw.reset(np.zeros(6))
    np.testing.assert_allclose(uw.update(uw.raw(w, x, twist, accel)), user, atol=1e-12)


def test_user_wrench_tare_dead_band_and_saturation():
    uw = UserWrench(MINI, DT, UserWrenchParams(T_filter=0.0, dead_band=[0.5, 0.02], w_max=[20.0, 0.5]))
    bias = np.array([0.3, -0.2, 0.4, 0.01, 0.0, 0.0])
    uw.reset(bias)                                        # tare at switch-on (the thesis' w_init)
    out = uw.update(bias + np.array([0.4, 2.0, -100.0, 0.05, 0.0, 9.0]))
    np.testing.assert_allclose(out, [0.0, 1.5, -20.0, 0.03, 0.0, 0.5], atol=1e-12)


def test_user_wrench_filter_is_the_pt1_of_5_9():
    uw = UserWrench(MINI, DT, UserWrenchParams(T_filter=0.003, dead_band=[0.0, 0.0], w_max=[100.0, 10.0]))
    uw.reset(np.zeros(6))
    y = [uw.update(np.r_[1.0, np.zeros(5)])[0] for _ in range(3)]
    assert y[-1] == pytest.approx(1.0 - np.exp(-1.0), rel=1e-12)      # one time constant


def test_switch_on_and_off_without_a_jump():
    """Enabled at a held pose: the first output is that pose; disabled while moving: it brakes at
    a_max to rest (velocity continuous) before handing back."""
    ctl = AdmittanceController(MINI, DT)
    x_hold = MINI.home + np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.0])          # zone 2: no spring
    w_static = gravity_wrench(MINI, x_hold) + np.r_[0.7, 0, 0, 0, 0, 0]   # a bias the tare removes
    out = ctl.step(w_static, x_hold)
    assert not out.active and np.array_equal(out.x, x_hold)
    ctl.enable()
    out = ctl.step(w_static, x_hold)
    np.testing.assert_allclose(out.x, x_hold, atol=1e-15)
    x, (xd, xdd) = out.x, out.twist()
    for _ in range(150):                                   # a push of 10 N in zone 2
        out = ctl.step(w_static + np.r_[10.0, 0, 0, 0, 0, 0], x, xd, xdd)
        x, (xd, xdd) = out.x, out.twist()
    assert out.zone == 1 and xd[0] > 0.05
    ctl.disable()
    v = [xd[0]]
    while True:
        out = ctl.step(w_static + np.r_[10.0, 0, 0, 0, 0, 0], x, xd, xdd)   # the user is ignored
        if not out.active:
            break
        x, (xd, xdd) = out.x, out.twist()
        v.append(xd[0])
    assert np.all(np.abs(np.diff(v)) <= ctl.system.a_max[0] * DT + 1e-12) and v[-1] == 0.0
    np.testing.assert_allclose(out.x, x)                   # inactive: follows the held set-point


def test_default_zones_fit_the_wrench_feasible_workspace_and_a_too_large_box_is_refused():
    for name in ("ipanema3_mini", "ipanema3"):
        settings_from({}, load_robot(name))
    with pytest.raises(ValueError, match="wrench-feasible"):
        settings_from({"zones.free.box": [0.3, 0.3, 0.3, 0.05, 0.05, 0.05]}, MINI)
    with pytest.raises(ValueError, match="rest sphere"):
        settings_from({"zones.rest.radius": 0.04}, MINI)


def test_box_from_workspace_is_the_border_of_the_wfw():
    """The largest box fits, 2 % more does not (the border comes from the WFW, section 2.2.1)."""
    params, zones, _ = settings_from({}, MINI)
    box = box_from_workspace(MINI, MINI.home, zones.box, params.user.w_max, params.v_max, zones, tol=1e-3)

    def zones_with(b):
        return ZoneSet(tuple(Zone(z.name, z.shape, b if z.shape == "box" else z.size, z.c, z.d, z.m, z.spring)
                             for z in zones.zones), zones.x_0)

    check_in_workspace(MINI, zones_with(box), params.user.w_max, params.v_max)
    with pytest.raises(ValueError):
        check_in_workspace(MINI, zones_with(1.02 * box), params.user.w_max, params.v_max)


def test_default_parameters_round_trip():
    params, zones, _ = settings_from(default_parameters(), MINI)
    ref_params = AdmittanceParams()
    for name in ("v_max", "a_max"):
        np.testing.assert_array_equal(np.repeat(getattr(ref_params, name), 3), getattr(params, name))
    for name in ("dead_band", "w_max"):
        np.testing.assert_array_equal(np.repeat(getattr(ref_params.user, name), 3), getattr(params.user, name))
    ref = thesis_zones(MINI.home)
    for a, b in zip(zones.zones, ref.zones):
        assert a.name == b.name and np.allclose(a.c, b.c) and np.allclose(a.d, b.d) and np.allclose(a.m, b.m)


@pytest.mark.parametrize("bad", [{"v_max": [0.0] * 6}, {"dead_band": [30.0] * 6}, {"zones.rest.m": [0.0] * 6},
                                 {"zones.wall.c": [-1.0] * 6}, {"T_filter": -1.0}, {"payload_mass": -1.0}])
def test_invalid_parameters_are_refused_with_a_reason(bad):
    with pytest.raises(ValueError):
        settings_from(bad, MINI)


@pytest.mark.parametrize("name", ["ipanema3_mini", "ipanema3"])
def test_shipped_parameter_files_are_valid_for_their_robot(name):
    import yaml
    from importlib import resources

    file = yaml.safe_load(resources.files("cdpr_control").joinpath("params", f"{name}.yaml").read_text())
    values = dict(file["admittance_controller"]["ros__parameters"])
    assert values.pop("hand_guiding") is False                  # off at start-up
    assert set(values) <= set(default_parameters())
    settings_from(values, load_robot(name))


# ---- zones near the border of the WFW: shrunk to fit, not refused --------------------------------

IPANEMA3 = load_robot("ipanema3")
# a border pose of the validation grid (ipanema3 #1, 98 % of its ray's border distance)
IPANEMA3_BORDER = [2.283, -3.842, 1.983, 0.0, 0.0, 0.0]


def _shipped_values(robot, x):
    from cdpr_control.control.params import load_params_file

    values = dict(load_params_file(robot.file.stem)["admittance_controller"])
    values.pop("hand_guiding")
    return {**values, "zones.origin": (np.asarray(x) - robot.home).tolist()}


def test_zones_that_fit_are_not_clipped():
    from cdpr_control.control.admittance import fitted_settings

    params, zones, _, clipping = fitted_settings(_shipped_values(IPANEMA3, IPANEMA3.home), IPANEMA3)
    assert clipping is None
    np.testing.assert_array_equal(zones.box, settings_from(_shipped_values(IPANEMA3, IPANEMA3.home), IPANEMA3)[1].box)


def test_zones_leaving_the_wfw_near_the_border_are_shrunk_to_the_largest_that_fits():
    from cdpr_control.control.admittance import fitted_settings
    from cdpr_control.control.admittance_zones import scaled

    values = _shipped_values(IPANEMA3, IPANEMA3_BORDER)
    with pytest.raises(ValueError, match="wrench-feasible"):
        settings_from(values, IPANEMA3)                            # as configured, it leaves the WFW
    params, zones, loaded, clipping = fitted_settings(values, IPANEMA3)
    configured = settings_from(values, IPANEMA3, check_workspace=False)[1]
    assert 0.0 < clipping.scale < 1.0
    np.testing.assert_allclose(zones.box, clipping.scale * configured.box)
    assert zones.zones[0].size == pytest.approx(clipping.scale * configured.zones[0].size)   # the rest sphere too
    np.testing.assert_array_equal(zones.x_0, IPANEMA3_BORDER)
    for a, b in zip(zones.zones, configured.zones):                # the dynamics are kept
        np.testing.assert_array_equal(a.c, b.c) and np.testing.assert_array_equal(a.m, b.m)
    limits = force_limits(IPANEMA3, values["zones.force_margin"])    # (the file's margin: fitted within them)
    check_in_workspace(loaded, zones, params.user.w_max, params.v_max, *limits)
    with pytest.raises(ValueError):                                 # the largest: 2 % more leaves it
        check_in_workspace(loaded, scaled(configured, 1.02 * clipping.scale), params.user.w_max, params.v_max, *limits)
    assert f"scaled by {clipping.scale:.3g}" in clipping.text() and "clipped" in clipping.text()


def test_where_not_even_the_walls_reach_fits_the_limits_shrink_with_the_zones():
    """Nearer the border the wall's reach (proportional to w_max and v_max) leaves the WFW with any
    box: zones, v_max and w_max are scaled by one factor, the largest that fits (w_max not
    below 1.25 x the dead band)."""
    from cdpr_control.control.admittance import fitted_settings
    from cdpr_control.control.admittance_zones import W_MAX_OVER_DEAD_BAND, per_axis, scaled

    # the grid's border pose: in the WFW of the shipped margin's limits (145-2955 N) not even the
    # wall's reach fits there (without the margin, 5 % further out)
    values = _shipped_values(IPANEMA3, IPANEMA3_BORDER)
    limits = force_limits(IPANEMA3, values["zones.force_margin"])
    configured_params, configured, _ = settings_from(values, IPANEMA3, check_workspace=False)
    w_max, v_max = (per_axis(v, "") for v in (configured_params.user.w_max, configured_params.v_max))
    floor = W_MAX_OVER_DEAD_BAND * per_axis(configured_params.user.dead_band, "")
    with pytest.raises(ValueError, match="wrench-feasible"):                      # box alone: none fits
        check_in_workspace(IPANEMA3, scaled(configured, 1e-3), w_max, v_max, *limits)
    params, zones, loaded, clipping = fitted_settings(values, IPANEMA3)
    k = clipping.reach_scale
    assert 0.0 < k < 1.0 and clipping.scale == k and "v_max and w_max scaled by" in clipping.text()
    np.testing.assert_allclose(params.v_max, k * v_max)
    np.testing.assert_allclose(params.user.w_max, np.maximum(k * w_max, floor))
    np.testing.assert_allclose(zones.box, k * configured.box)
    check_in_workspace(loaded, zones, params.user.w_max, params.v_max, *limits)
    with pytest.raises(ValueError):                                  # the largest
        check_in_workspace(loaded, scaled(configured, 1.02 * k), np.maximum(1.02 * k * w_max, floor), 1.02 * k * v_max,
                           *limits)


def test_where_nothing_fits_hand_guiding_is_refused_with_the_reason():
    from cdpr_control.control.admittance import fitted_settings

    x = np.array(IPANEMA3_BORDER)
    x[:3] = IPANEMA3.home[:3] + (x[:3] - IPANEMA3.home[:3]) * 1.08     # 8 % further out, still in the WFW
    with pytest.raises(ValueError, match="no virtual workspace fits"):
        fitted_settings({**_shipped_values(IPANEMA3, x), "dead_band": [90.0, 90.0, 90.0, 9.0, 9.0, 9.0]}, IPANEMA3)


# ---- the force margin of the fit (zones.force_margin) ----------------------------------------------

# the validation grid's Mini pose #1 (border): released after a push against the wall, the platform
# rested at the free box's border with a cable planned at 39.74 N and truly at 40.31 N (f_max 40 N)
MINI_BORDER = [-0.0628, -0.2046, -0.0118, 0.0, 0.0, 0.0]


def test_force_limits_narrow_the_cable_limits_by_the_margin():
    f_min, f_max = force_limits(MINI, 1.0)
    np.testing.assert_array_equal(f_min, MINI.cable.f_min + 1.0)
    np.testing.assert_array_equal(f_max, MINI.cable.f_max - 1.0)
    for bad in (-0.1, 17.5):                                     # negative; nothing left of 5-40 N
        with pytest.raises(ValueError, match="force_margin"):
            force_limits(MINI, bad)


def test_the_zones_are_fitted_within_the_force_margin():
    """With the Mini's margin (1 N) the hard box lies in the WFW of [6, 39] N, a smaller box than
    without it, which leaves those limits."""
    from cdpr_control.control.admittance import fitted_settings

    values = _shipped_values(MINI, MINI_BORDER)
    assert values["zones.force_margin"] == 1.0                  # the shipped file's
    limits = force_limits(MINI, 1.0)
    params, zones, loaded, clipping = fitted_settings(values, MINI)
    plain_params, without, _, plain = fitted_settings({**values, "zones.force_margin": 0.0}, MINI)
    assert clipping.scale < plain.scale
    check_in_workspace(loaded, zones, params.user.w_max, params.v_max, *limits)
    with pytest.raises(ValueError, match="wrench-feasible"):
        check_in_workspace(loaded, without, plain_params.user.w_max, plain_params.v_max, *limits)
    check_in_workspace(loaded, without, plain_params.user.w_max, plain_params.v_max)   # (the cable limits')
