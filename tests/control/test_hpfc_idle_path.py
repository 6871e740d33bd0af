"""The idle path of the hybrid force controller (HybridForceControl._idle_state: state I while not
wanted) and the hand-over's NO_HAND_OVER against the full path (``idle_path = False``): the same
numbers bit for bit (signs of zero included) period by period, through idle periods disabled and
enabled below F_th, an approach, contact, the release and idle again, with the task axis changing
while idle, a tared contact force, non-finite inputs and the CFC's output switched."""
import math

import numpy as np

from cdpr_control.control.filters import LowPass
from cdpr_control.control.hybrid_force_control import (IDLE, NO_HAND_OVER, ContactHandOver, HPFCParams, HPFCState,
    HybridForceStage)
from cdpr_control.model.robot import load_robot

MINI = load_robot("ipanema3_mini")
PARAMS = HPFCParams(F_th=3.0, K_p=5000.0, T_F=0.01, x_max=0.02, T_on=0.05)
DT = 1e-3
FIELDS = ("state", "active", "z_t", "F_d0", "F_vec", "F_d", "F", "e_F", "x_t", "v_t", "integrator", "saturated", "x")


def bits(value):
    """What distinguishes two values bit for bit (-0.0 from 0.0 too)."""
    if isinstance(value, np.ndarray):
        return value.dtype.str, value.shape, value.tobytes()
    if isinstance(value, float):
        return value.hex()
    return value


def program():
    """(period, enabled, F_d,0 (3,), contact stiffness [N/m] of a floor below the platform, wrench noise)."""
    rng = np.random.default_rng(7)
    down = np.array([0.0, 0.0, -6.0])              # task axis -z: x = x_t z_t has -0.0 where x_t = 0
    for k in range(3000):
        if k < 200:
            enabled, F_d0 = False, down                       # disabled (not wanted)
        elif k < 400:
            enabled, F_d0 = True, np.array([0.0, 0.0, -1.0])  # enabled, F_d < F_th (not wanted, active)
        elif k < 420:
            enabled, F_d0 = True, np.array([np.nan, 0.0, 0.0])  # no valid demand: released, idle
        elif k < 1600:
            enabled, F_d0 = True, down                        # approach, contact, force control
        elif k < 2200:
            enabled, F_d0 = True, np.zeros(3)                 # release, then idle with the axis kept
        elif k < 2400:
            enabled, F_d0 = False, np.array([3.0, 4.0, 0.0])  # idle, the axis turns
        else:
            enabled, F_d0 = False, np.zeros(3)
        yield k, enabled, F_d0, 20000.0, rng.normal(0.0, 0.05, 6)


def wrench(control, stiffness, noise, k):
    """The measured wrench: weight, a floor 1 mm along -z from where x_t starts, noise, a
    non-finite sample now and then."""
    if k in (150, 1000, 2300):
        return np.full(6, np.nan)
    press = stiffness * max(0.0, control.x_t - 1e-3)
    w = np.zeros(6)
    w[:3] = control.weight + press * np.array([0.0, 0.0, 1.0]) + 0.2   # (0.2 N: a sensor offset the tare takes)
    return w + noise


def run(idle_path: bool):
    stage = HybridForceStage(MINI, DT, PARAMS, T_c=0.05)
    stage.control.idle_path = idle_path
    reference = HybridForceStage(MINI, DT, PARAMS, T_c=0.05)    # the plant's x_t, the same for both runs
    reference.control.idle_path = False
    rows = []
    for k, enabled, F_d0, stiffness, noise in program():
        stage.control.enabled = reference.control.enabled = enabled
        w = wrench(reference.control, stiffness, noise, k)
        cfc_on = not 1700 <= k < 1750
        for s_ in (stage, reference):
            if s_.control.state == "D":
                s_.take_over(0.01)
        s, out = stage.update(F_d0, w, cfc_on)
        reference.update(F_d0, w, cfc_on)
        c = stage.control
        rows.append(([bits(getattr(s, f)) for f in FIELDS], bits(out),
                     bits(c.F_prev), c.active_periods, bits(c.x_t), bits(c.integrator), s))
    return rows


def test_the_idle_path_computes_the_full_paths_numbers_bit_for_bit():
    fast, full = run(True), run(False)
    states = "".join(row[-1].state for row in full)
    # the program goes through every idle case and the contact states
    assert states[:420] == "I" * 420 and {"A", "B", "D", "R"} <= set(states) and states[-800:] == "I" * 800
    assert states.count("D") > 300
    for k, (a, b) in enumerate(zip(fast, full)):
        assert a[:-1] == b[:-1], (k, states[k])
    # the idle path was taken: its periods share read-only arrays while z_t, F_d,0 and x_t stay
    s1, s2 = fast[100][-1], fast[101][-1]
    assert s1.z_t is s2.z_t and s1.x is s2.x and s1.F_d0 is s2.F_d0
    assert not (s1.z_t.flags.writeable or s1.x.flags.writeable or s1.F_d0.flags.writeable)
    assert full[100][-1].z_t is not full[101][-1].z_t
    # the axis of -z left -0.0 in x after the release (x = 0 z_t)
    late = fast[2100][-1]
    assert late.state == IDLE and math.copysign(1.0, late.x[2]) == -1.0


def test_no_hand_over_is_the_shared_read_only_zero():
    hand_over = ContactHandOver(0.3, DT)
    stage = HybridForceStage(MINI, DT, PARAMS)
    stage.control.z_t = np.array([0.0, 0.0, -1.0])     # the axis after a contact on a floor (kept: F_d,0 = 0)
    s, out = stage.update(np.zeros(3), np.r_[stage.control.weight, 0.0, 0.0, 0.0], True)
    assert hand_over.update(s, 5000.0, False) is NO_HAND_OVER          # the CFC's output not applied
    assert hand_over.update(s, 5000.0, True) is NO_HAND_OVER           # idle, no contact force
    assert not NO_HAND_OVER.flags.writeable and not NO_HAND_OVER.any()
    # x = 0 z_t has -0.0 along z; the output x + x_comp had 0.0 there, as x + 0.0 has
    assert math.copysign(1.0, s.x[2]) == -1.0 and out.tobytes() == np.zeros(6).tobytes()


def test_the_hand_over_filter_and_x_comp_through_a_contact():
    """ContactHandOver's PT1 output and x_comp against a PT1 updated every period: through a
    contact, the decay after it, inputs of -0.0 and 0.0 at rest, and resets of the filter."""
    T_c, k_t = 0.05, 5000.0
    hand_over, reference = ContactHandOver(T_c, DT), LowPass(T_c, DT)
    z = np.array([0.0, 0.0, -1.0])
    states = ["I"] * 50 + ["A"] * 20 + ["D"] * 200 + ["R"] * 30 + ["I"] * 300 + ["D"] * 10 + ["I"] * 40
    for k, state in enumerate(states):
        F_d = -0.0 if k % 7 == 0 else (0.0 if state == "I" else 6.0)
        if k in (10, 20):                      # at rest: a reset elsewhere ends the rest
            hand_over.filter.reset(3.0 if k == 10 else 0.0)
            reference.reset(3.0 if k == 10 else 0.0)
        s = HPFCState(state, True, z, F_d * -z, np.zeros(3), F_d, 0.0, F_d, 0.0, 0.0, 0.0, False, np.zeros(6))
        x_comp = hand_over.update(s, k_t, True)
        F_c, = reference.update_floats((F_d if state != "I" else 0.0,))
        assert float(np.ravel(hand_over.filter.y)[0]).hex() == F_c.hex(), k
        if F_c == 0.0 or state in "ABC":
            assert x_comp is NO_HAND_OVER, k
        else:
            assert x_comp.tobytes() == np.r_[-hand_over.share * F_c / k_t * z if state in "DR" else -F_c / k_t * z,
                                             np.zeros(3)].tobytes(), k
