"""Offset inputs of the joint command (5.1)/(5.10): sum, ramped switching, deadlines, bad values."""
import numpy as np
import pytest

from cdpr_control.control.offset_inputs import OffsetConfig, OffsetInputs, OffsetSample
from cdpr_control.control.safety import NON_FINITE, STALE_INPUT

DT = 0.001


def _run(offsets, periods, samples_at):
    """Totals of ``periods`` updates, samples from ``samples_at(k, t)``."""
    out = []
    for k in range(periods):
        t = k * DT
        total, faults = offsets.update(t, samples_at(k, t))
        out.append((total, faults))
    return out


def test_active_inputs_add_up_after_the_ramp():
    a, b = np.arange(6) * 1e-3, np.full(6, -2e-4)
    offsets = OffsetInputs(["ospc", "lc"], DT, ramp_time=0.01)
    out = _run(offsets, 20, lambda k, t: {"ospc": OffsetSample(t, True, a), "lc": OffsetSample(t, True, b)})
    np.testing.assert_allclose(out[-1][0], a + b, atol=1e-15)
    # during the ramp the contribution is alpha * x with alpha = k dt / ramp_time
    np.testing.assert_allclose(out[4][0], 0.5 * (a + b), atol=1e-15)
    assert not any(faults for _, faults in out)


def test_switching_off_ramps_the_last_value_out_linearly():
    x = np.array([0.01, 0, -0.02, 0, 0.001, 0])
    offsets = OffsetInputs(["hpfc"], DT, ramp_time=0.0)
    offsets.update(0.0, {"hpfc": OffsetSample(0.0, True, x)})
    offsets.configure({}, ramp_time=0.004)
    # the producer switches itself off: its output is zero but the contribution ramps out
    totals = [offsets.update(k * DT, {"hpfc": OffsetSample(k * DT, False, np.zeros(6))})[0] for k in range(1, 6)]
    np.testing.assert_allclose([t[2] for t in totals], [-0.015, -0.01, -0.005, 0.0, 0.0], atol=1e-15)
    steps = np.abs(np.diff([x, *totals], axis=0))
    assert steps.max() <= np.abs(x).max() * DT / 0.004 + 1e-15          # never more than one ramp step


def test_disabled_by_config_contributes_nothing_and_is_not_a_fault():
    offsets = OffsetInputs(["adm"], DT, ramp_time=0.0, configs={"adm": OffsetConfig(enabled=False)})
    total, faults = offsets.update(0.0, {"adm": OffsetSample(0.0, True, np.ones(6))})
    assert not np.any(total) and not faults


def test_stale_active_input_is_a_holding_fault_silent_inactive_one_is_not():
    offsets = OffsetInputs(["ospc", "hpfc"], DT, ramp_time=0.0,
                           configs={"ospc": OffsetConfig(deadline=0.005)})
    old = OffsetSample(0.0, True, np.full(6, 1e-3))
    total, faults = offsets.update(0.006, {"ospc": old, "hpfc": None})
    assert [f.code for f in faults] == [STALE_INPUT] and faults[0].holds and "ospc" in faults[0].message
    total, faults = offsets.update(0.004, {"ospc": old})
    assert not faults


@pytest.mark.parametrize("x", [np.full(6, np.nan), np.array([np.inf, 0, 0, 0, 0, 0]), np.zeros(3)])
def test_non_finite_or_misshaped_input_holds_and_never_reaches_the_sum(x):
    offsets = OffsetInputs(["lc"], DT, ramp_time=0.0)
    offsets.update(0.0, {"lc": OffsetSample(0.0, True, np.full(6, 1e-3))})
    total, faults = offsets.update(DT, {"lc": OffsetSample(DT, True, x)})
    assert [f.code for f in faults] == [NON_FINITE] and faults[0].holds
    assert np.all(np.isfinite(total))


def test_bad_configuration_is_refused_with_the_reason():
    with pytest.raises(ValueError, match="unique"):
        OffsetInputs(["ospc", "ospc"], DT, 0.2)
    offsets = OffsetInputs(["ospc"], DT, 0.2)
    with pytest.raises(ValueError, match="unknown offset inputs"):
        offsets.configure({"hpfc": OffsetConfig()}, 0.2)
    with pytest.raises(ValueError, match="deadline"):
        offsets.configure({"ospc": OffsetConfig(deadline=0.0)}, 0.2)
    with pytest.raises(ValueError, match="ramp time"):
        offsets.configure({}, -1.0)
