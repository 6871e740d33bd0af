"""The force watch's safe outputs when the force set-point comes after the first command (issue 28:
a push in the first periods got no tension correction)."""
import numpy as np

from cdpr_control.control.safety import ForceWatch, SafetyConfig

DT = 1e-3
M = 8
F_MIN, F_MAX = np.full(M, 5.0), np.full(M, 40.0)


def test_a_trip_before_the_first_clean_stretch_holds_the_first_force_set_point_given():
    """In the graph the force distribution's f_d may arrive a period after the first command: the
    first period's outputs (the safe ones before any clean stretch of safe_history) then had no
    f_d, and the hold restored no tension (joint_command: no f_d,safe, no correction). Now the first
    f_d given fills them; the offsets and Δq_CFC stay the first period's."""
    watch = ForceWatch(SafetyConfig(), DT)
    f_d = np.full(M, 10.0)
    watch.update(np.full(M, 10.0), F_MIN, F_MAX, np.zeros(6), np.full(6, 1.0), np.full(M, 1.0), None)
    for k in range(2, 20):
        watch.update(np.full(M, 10.0), F_MIN, F_MAX, np.zeros(6), np.full(6, float(k)), np.full(M, float(k)), f_d)
    assert watch.fault is None
    for k in range(20, 200):                  # a push: far beyond the band until the watch trips
        if watch.update(np.full(M, 300.0), F_MIN, F_MAX, np.zeros(6), np.zeros(6), np.zeros(M), f_d) is not None:
            break
    assert watch.fault is not None
    x_safe, offset, dq_cfc, f_d_safe = watch.safe
    np.testing.assert_array_equal(offset, np.full(6, 1.0))
    np.testing.assert_array_equal(dq_cfc, np.full(M, 1.0))
    np.testing.assert_array_equal(f_d_safe, f_d)
