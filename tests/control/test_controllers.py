"""PI core, cable force control (3.19)-(3.23), OSPC (3.16) and the Smith-predictor wrench (3.26)."""
import numpy as np
import pytest

from cdpr_control.control.cable_force_control import CableForceController, CFCParams, widened_saturation
from cdpr_control.control.ospc import OperationalSpacePositionController, OSPCParams
from cdpr_control.control.pi_control import PIController
from cdpr_control.control.wrench_setpoint import WrenchSetpoint


def test_pi_matches_discrete_formula_in_the_linear_range():
    pi = PIController(2, K_p=[2.0, 0.5], T_i=[0.1, np.inf], u_neg=100, u_pos=100, dt=0.01)
    e = np.array([1.0, 1.0])
    for k in range(1, 6):
        u = pi.update(e)
        np.testing.assert_allclose(u, [2.0 + 2.0 * 0.01 / 0.1 * k, 0.5])


def test_pi_anti_windup_leaves_saturation_at_once():
    pi = PIController(1, K_p=1.0, T_i=0.05, u_neg=1.0, u_pos=1.0, dt=0.001)
    for _ in range(5000):                     # 5 s pushing into the positive limit
        pi.update(np.array([10.0]))
    assert pi.saturated[0] and pi.output[0] == 1.0
    assert pi.integrator[0] <= 1.0            # no wind-up beyond the output range
    u = pi.update(np.array([-0.5]))           # error reverses: output must drop below the limit now
    assert u[0] < 1.0


def test_pi_hold_keeps_the_integrator():
    """hold (bumpless transfer in the node graph): the output is K_p e + I, the integrator unchanged."""
    pi = PIController(1, K_p=2.0, T_i=0.1, u_neg=3.0, u_pos=3.0, dt=0.01)
    pi.update(np.array([1.0]))
    pi.hold = True
    for _ in range(100):
        u = pi.update(np.array([1.0]))
    assert pi.integrator[0] == pytest.approx(0.2) and u[0] == pytest.approx(2.2)
    assert pi.update(np.array([2.0]))[0] == 3.0 and pi.saturated[0]       # clipped, still held
    pi.hold = False
    assert pi.update(np.array([0.5]))[0] == pytest.approx(1.0 + 0.2 + 0.1)


def test_pi_rejects_bad_gains():
    with pytest.raises(ValueError):
        PIController(1, K_p=-1.0, T_i=0.1, u_neg=1, u_pos=1, dt=0.001)
    with pytest.raises(ValueError):
        PIController(1, K_p=1.0, T_i=0.0, u_neg=1, u_pos=1, dt=0.001)


def _cable_plant(k_true, dq_0, dt, T_drive=0.005):
    """A PT1 drive shortens the winch by dq_cfc; the cable pulls k_true (dq_cfc + dq_0)."""
    state = {"dq": np.zeros_like(dq_0)}
    alpha = 1.0 - np.exp(-dt / T_drive)

    def step(dq_cfc):
        state["dq"] = state["dq"] + alpha * (dq_cfc - state["dq"])
        return k_true * (state["dq"] + dq_0)

    return step


def test_cfc_reaches_desired_force_despite_wrong_stiffness_model():
    dt, m = 0.001, 3
    k_model = np.array([1.0e5, 2.0e5, 3.0e5])
    k_true = 1.3 * k_model                    # the linear model underestimates the progressive cable
    dq_0 = np.array([1e-3, 5e-4, 2e-4])
    plant = _cable_plant(k_true, dq_0, dt)
    cfc = CableForceController(m, CFCParams(), dt)          # table 3.1 gains and filter
    cfc.reset(dq_0)
    f_d = np.array([150.0, 300.0, 120.0])
    f = plant(np.zeros(m))
    for _ in range(10000):
        f = plant(cfc.update(f_d, f, k_model, np.full(m, 100.0), np.full(m, 3000.0)))
    np.testing.assert_allclose(f, f_d, rtol=1e-6)
    # the integrator holds exactly the part the stiffness model gets wrong
    np.testing.assert_allclose(cfc.f_out, f_d * k_model / k_true, rtol=1e-6)


def test_cfc_output_formula_3_23():
    cfc = CableForceController(2, CFCParams(T_filter=0.0, K_p=0.0), 0.001)
    dq_0 = np.array([0.001, 0.002])
    cfc.reset(dq_0)
    k_l = np.array([2e5, 4e5])
    f_d = np.array([300.0, 400.0])
    dq = cfc.update(f_d, f_d, k_l, np.zeros(2), np.full(2, 1e4))
    np.testing.assert_allclose(dq, f_d / k_l - dq_0)     # K_p = 0: pure feed-forward (3.22)


def test_cfc_saturation_widens_near_limits():
    p = CFCParams(F_sat_n=100.0, F_sat_p=100.0, widen_band=50.0, widen_factor=3.0)
    sat_n, sat_p = widened_saturation(p, np.array([100.0, 125.0, 1000.0, 2975.0, 3000.0]), 100.0, 3000.0)
    np.testing.assert_allclose(sat_p, [300.0, 200.0, 100.0, 100.0, 100.0])
    np.testing.assert_allclose(sat_n, [100.0, 100.0, 100.0, 200.0, 300.0])


def test_cfc_feedback_filter_is_pt1():
    dt, T = 0.001, 0.08
    cfc = CableForceController(1, CFCParams(T_filter=T), dt)
    cfc.reset([0.0], f=[0.0])
    for _ in range(80):
        y = cfc.filter(np.array([1.0]))
    assert y[0] == pytest.approx(1.0 - np.exp(-1.0), rel=1e-9)   # one time constant


def test_cfc_rejects_bad_params_and_keeps_old():
    cfc = CableForceController(1, CFCParams(), 0.001)
    with pytest.raises(ValueError, match="T_i"):
        cfc.set_params(CFCParams(T_i=-1.0))
    assert cfc.params.T_i == 0.1


def test_ospc_removes_static_sag():
    dt = 0.01
    ospc = OperationalSpacePositionController(OSPCParams(), dt)
    x_d = np.array([0.1, 0.0, 0.5, 0.0, 0.0, 0.0])
    sag = np.array([0.0, 0.0, -0.004, 0.001, 0.0, 0.0])   # elastic deflection under load
    x_ospc = np.zeros(6)
    for _ in range(6000):                                   # 60 s: integral time K_p/T_i = 0.39/s
        x = x_d + x_ospc + sag                              # quasi-static plant
        x_ospc = ospc.update(x_d, x)
    np.testing.assert_allclose(x_d + x_ospc + sag, x_d, atol=1e-9)


def test_ospc_output_saturates():
    ospc = OperationalSpacePositionController(OSPCParams(x_sat=np.full(6, 0.01)), 0.001)
    for _ in range(5000):
        out = ospc.update(np.full(6, 1.0), np.zeros(6))
    np.testing.assert_allclose(out, 0.01)


def test_smith_predictor_delays_by_T_d_w():
    ws = WrenchSetpoint(T_d_w=0.01, dt=0.001)
    assert ws.delay == 10
    w_dyn = np.zeros(6)
    outputs = []
    for k in range(30):
        w_dyn = np.full(6, 1.0) if k >= 5 else np.zeros(6)       # step in the expected inertia wrench
        outputs.append(ws.update(np.zeros(6), w_dyn)[0])
    outputs = np.array(outputs)
    # (I - e^{-T s}) applied to a step: a pulse of exactly `delay` periods
    np.testing.assert_array_equal(outputs, [0.0] * 5 + [1.0] * 10 + [0.0] * 15)


def test_smith_predictor_measured_delayed_inertia_is_anticipated():
    """If the measured wrench carries w_dyn after T_d,w, then w_d equals w_dyn at once."""
    ws = WrenchSetpoint(T_d_w=0.005, dt=0.001)
    history = []
    for k in range(40):
        w_dyn = np.full(6, np.sin(0.3 * k))
        history.append(w_dyn)
        measured = history[k - 5] if k >= 5 else np.zeros(6)
        w_d = ws.update(measured, w_dyn)
        np.testing.assert_allclose(w_d, w_dyn, atol=1e-12)
