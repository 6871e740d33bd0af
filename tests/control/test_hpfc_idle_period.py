"""HybridForceStage._idle_period (the held idle period without its constant work) serves the idle
periods, and only those: the full path (HybridForceControl.update) runs in the first period (the
hand-over's filter not yet at +0.0) and wherever a condition fails, and every period's numbers equal
the full path's bit for bit (tests/control/test_hpfc_idle_path.py goes through contact too)."""
import numpy as np

from cdpr_control.control.hybrid_force_control import HPFCParams, HybridForceControl, HybridForceStage
from cdpr_control.model.robot import load_robot

MINI = load_robot("ipanema3_mini")
PARAMS = HPFCParams(F_th=3.0, K_p=5000.0, T_F=0.01, x_max=0.02, T_on=0.05)
FIELDS = ("state", "active", "z_t", "F_d0", "F_vec", "F_d", "F", "e_F", "x_t", "v_t", "integrator", "saturated", "x")


def bits(value):
    if isinstance(value, np.ndarray):
        return value.dtype.str, value.shape, value.tobytes()
    if isinstance(value, float):
        return value.hex()
    return value


class Counted(HybridForceControl):
    full = 0

    def update(self, F_d0, w, x_d=None, limits=None):
        self.full += 1
        return super().update(F_d0, w, x_d, limits)


def test_held_idle_periods_skip_the_full_path_with_the_same_numbers():
    stage = HybridForceStage(MINI, 1e-3, PARAMS, T_c=0.05)
    stage.control = Counted(MINI, 1e-3, PARAMS)
    reference = HybridForceStage(MINI, 1e-3, PARAMS, T_c=0.05)
    reference.control.idle_path = False
    rng = np.random.default_rng(3)
    F_d0 = np.array([0.0, 0.0, -6.0])         # disabled: not wanted; x = [-0.0, ...] + 0.0
    weight = stage.control.weight
    full = []
    for k in range(300):
        w = np.zeros(6)
        w[:3] = weight + rng.normal(0.0, 0.05, 3)
        if k == 100:
            w[2] = np.nan                     # a non-finite wrench: the full path keeps the estimate
        if k == 200:
            F_d0 = np.array([3.0, 4.0, 0.0])  # a new F_d,0: its axis in the full path, then idle again
        before = stage.control.full
        s, out = stage.update(F_d0, w, True)
        r, out_r = reference.update(F_d0, w, True)
        assert [bits(getattr(s, f)) for f in FIELDS] == [bits(getattr(r, f)) for f in FIELDS], k
        assert bits(out) == bits(out_r) and out.tobytes() == (r.x + 0.0).tobytes(), k
        if stage.control.full > before:
            full.append(k)
    assert full == [0, 100, 200]
