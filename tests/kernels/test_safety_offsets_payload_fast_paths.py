"""The per-period fast paths of the joint command's safety monitor and offset inputs and of the
force distribution's payload wrench on random inputs: the monitor reports exactly the faults its
bounds define (an oracle written from the definitions, vectorised), the offset inputs and payload
wrench give the numbers of the code they replaced bit for bit.
"""
import numpy as np
import pytest

from cdpr_control.control import load_compensation as lcm
from cdpr_control.control.offset_inputs import OffsetConfig, OffsetInputs, OffsetSample
from cdpr_control.control.safety import (FK_NOT_CONVERGED, FORCE_LIMIT, NON_FINITE, POSITION_LAG, STALE_INPUT,
    Fault, SafetyConfig, SafetyMonitor, all_finite)
from cdpr_control.model.robot import load_robot


def same(a, b) -> bool:
    """Bit-equal: the same float64 bytes (so -0.0 differs from 0.0 and a NaN equals itself)."""
    return np.asarray(a, dtype=float).tobytes() == np.asarray(b, dtype=float).tobytes()


def expected_faults(c: SafetyConfig, now, *, f=None, f_min=None, f_max=None, x_d=None, x=None,
                    fk_converged=True, input_times=None) -> list[tuple[str, bool, str]]:
    """What the monitor must report, from the bounds' definitions (docs/control.md, safety), as
    (code, holds, a word its message must name), in report order: non-finite inputs, each cable
    outside [f_min - tol, f_max + tol] (below first, then above), the position and orientation lag,
    forward kinematics, each stale input."""
    given = {"f": f, "x_d": x_d, "x": x}
    finite = {k: v is not None and bool(np.isfinite(np.asarray(v, dtype=float)).all()) for k, v in given.items()}
    out = [(NON_FINITE, True, f"{k} has") for k, v in given.items() if v is not None and not finite[k]]
    if finite["f"]:
        forces = np.asarray(f, dtype=float)
        low = np.asarray(f_min, dtype=float) - c.force_tolerance
        high = np.asarray(f_max, dtype=float) + c.force_tolerance
        out += [(FORCE_LIMIT, c.hold_on_force_limit, f"cable {i + 1}: ") for i in np.flatnonzero(forces < low)]
        out += [(FORCE_LIMIT, c.hold_on_force_limit, f"cable {i + 1}: ") for i in np.flatnonzero(forces > high)]
    if finite["x_d"] and finite["x"]:
        e = np.asarray(x_d, dtype=float) - np.asarray(x, dtype=float)
        if np.linalg.norm(e[:3]) > c.max_position_lag:
            out.append((POSITION_LAG, True, "position lag"))
        if np.linalg.norm(e[3:]) > c.max_orientation_lag:
            out.append((POSITION_LAG, True, "orientation lag"))
    if not fk_converged:
        out.append((FK_NOT_CONVERGED, True, "forward kinematics"))
    out += [(STALE_INPUT, True, f"input {name}:") for name, t in (input_times or {}).items()
            if now - t > c.stale_timeout]                       # (a NaN time is not stale)
    return out


def reported(faults) -> list[tuple[str, bool, str]]:
    return [(fault.code, fault.holds, fault.message) for fault in faults]


def matches(got, expected) -> bool:
    return len(got) == len(expected) and all(
        (code, holds) == (e_code, e_holds) and word in message
        for (code, holds, message), (e_code, e_holds, word) in zip(reported(got), expected))


def _maybe_bad(rng, v, p=0.05):
    """v with, rarely, a NaN or an infinity in it."""
    v = np.array(v, dtype=float)
    if rng.random() < p:
        v[rng.integers(v.size)] = rng.choice([np.nan, np.inf, -np.inf])
    return v


@pytest.mark.parametrize("seed", range(4))
def test_safety_monitor_reports_the_faults_its_bounds_define(seed):
    """Random periods near and beyond every bound (force limits that change now and then, NaN and
    infinite values, stale and NaN input times, a missing input): the same faults in the same order."""
    rng = np.random.default_rng(seed)
    config = SafetyConfig(force_tolerance=float(rng.choice([0.0, 1.75])), max_position_lag=0.02,
                          stale_timeout=0.05, hold_on_force_limit=bool(seed % 2))
    monitor = SafetyMonitor(config)
    m = 8
    f_min, f_max = np.full(m, 5.0), np.full(m, 40.0)
    f_min.setflags(write=False)
    f_max.setflags(write=False)
    n_faults = 0
    for k in range(3000):
        now = 3.0 + k * 1e-3
        if rng.random() < 0.01:          # new limits (another array, or the same values as a list)
            f_min = rng.uniform(0.0, 10.0, m)
            f_max = f_min + rng.uniform(20.0, 40.0, m)
        limits = (f_min.tolist(), f_max.tolist()) if rng.random() < 0.05 else (f_min, f_max)
        f = _maybe_bad(rng, rng.uniform(0.0, 50.0, m) if rng.random() < 0.2 else rng.uniform(8.0, 35.0, m))
        x_d = _maybe_bad(rng, rng.normal(0.0, 0.01, 6))
        x = _maybe_bad(rng, x_d + rng.normal(0.0, 0.02, 6))
        times = {name: now - float(rng.choice([0.0, 0.001, 0.05, 0.0501, 0.2])) for name in ("a", "b", "c", "d")}
        if rng.random() < 0.05:
            times[str(rng.choice(list(times)))] = np.nan
        kwargs = dict(f=None if rng.random() < 0.05 else f, f_min=limits[0], f_max=limits[1],
                      x_d=None if rng.random() < 0.05 else x_d, x=x, fk_converged=bool(rng.random() > 0.02),
                      input_times=times if rng.random() > 0.05 else None)
        if kwargs["f"] is not None and isinstance(limits[0], list):
            kwargs["f_min"], kwargs["f_max"] = np.asarray(limits[0]), np.asarray(limits[1])
        got = monitor.check(now, **kwargs)
        assert matches(got, expected_faults(config, now, **kwargs)), (reported(got), kwargs)
        n_faults += len(got)
    assert n_faults > 1000                   # (the faults were exercised)


def test_safety_monitor_limits_of_another_dtype_or_in_place_changes():
    """The limits kept from an earlier period are those of the same bytes and dtype only."""
    config = SafetyConfig(force_tolerance=0.5)
    monitor = SafetyMonitor(config)
    f_min, f_max = np.full(4, 5.0), np.full(4, 40.0)
    f = np.array([10.0, 4.8, 20.0, 30.0])
    assert monitor.check(0.0, f=f, f_min=f_min, f_max=f_max) == []
    f_min[1] = 5.5                          # changed in place: a fault now
    got = monitor.check(0.0, f=f, f_min=f_min, f_max=f_max)
    assert matches(got, expected_faults(config, 0.0, f=f, f_min=f_min, f_max=f_max)) and len(got) == 1
    for lo, hi in ((f_min.astype(np.float32), f_max.astype(np.float32)), (f_min.astype(">f8"), f_max.astype(">f8")),
                   (np.array([5, 6, 5, 5]), np.array([40, 40, 40, 40]))):
        got = monitor.check(0.0, f=f, f_min=lo, f_max=hi)
        assert matches(got, expected_faults(config, 0.0, f=f, f_min=lo, f_max=hi)) and got
    with pytest.raises(ValueError):          # empty limits for forces: refused
        monitor.check(0.0, f=f, f_min=np.zeros(0), f_max=np.zeros(0))


class ReferenceOffsetInputs(OffsetInputs):
    """OffsetInputs.update as it was: the sum on numpy arrays."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.last = {n: np.zeros(6) for n in self.names}

    def reset(self):
        for name in self.names:
            self.alpha[name] = 0.0
            self.last[name] = np.zeros(6)

    def update(self, now, samples):
        total = np.zeros(6)
        faults = []
        step = 1.0 if self.ramp_time == 0.0 else self.dt / self.ramp_time
        for name in self.names:
            sample = samples.get(name)
            active = self.configs[name].enabled and sample is not None and sample.active
            if active:
                age = now - sample.t
                x = np.asarray(sample.x, dtype=float)
                if age > self.configs[name].deadline:
                    faults.append(Fault(STALE_INPUT, f"stale input offset {name}: older than its deadline "
                                        f"{1e3 * self.configs[name].deadline:.0f} ms", True))
                    active = False
                elif x.shape != (6,) or not all_finite(x.tolist()):
                    faults.append(Fault(NON_FINITE, f"offset {name} is not 6 finite values: {x}", True))
                    active = False
                else:
                    self.last[name] = x
            alpha = min(1.0, self.alpha[name] + step) if active else max(0.0, self.alpha[name] - step)
            self.alpha[name] = alpha
            if alpha:
                total += alpha * self.last[name]
        return total, faults


@pytest.mark.parametrize("seed", range(4))
def test_offset_inputs_sum_and_faults_of_the_reference(seed):
    """Inputs switched on and off at random (ramps in and out), stale, non-finite, of the wrong shape,
    with -0.0 and tiny values, reconfigured and reset now and then: the same totals bit for bit, the
    same faults and ramp states."""
    rng = np.random.default_rng(seed)
    names = ["ospc", "hybrid_force_controller", "load_compensation"]
    ramp = float(rng.choice([0.0, 0.005, 0.5]))
    fast, ref = OffsetInputs(names, 0.001, ramp), ReferenceOffsetInputs(names, 0.001, ramp)
    n_faults = 0
    for k in range(4000):
        now = k * 1e-3
        if rng.random() < 0.01:
            configs = {n: OffsetConfig(enabled=bool(rng.random() < 0.8), deadline=float(rng.choice([0.001, 0.005])))
                       for n in names if rng.random() < 0.5}
            ramp = float(rng.choice([0.0, 0.003, 0.5]))
            fast.configure(configs, ramp)
            ref.configure({n: OffsetConfig(c.enabled, c.deadline) for n, c in configs.items()}, ramp)
        if rng.random() < 0.002:
            fast.reset()
            ref.reset()
        samples = {}
        for name in names:
            if rng.random() < 0.1:
                continue                                  # no message
            x = rng.normal(0.0, 1e-3, 6) * rng.choice([1.0, 1e-300])
            x[rng.random(6) < 0.1] = -0.0
            r = rng.random()
            if r < 0.01:
                x[rng.integers(6)] = rng.choice([np.nan, np.inf])
            elif r < 0.015:
                x = np.zeros(5)
            age = float(rng.choice([0.0, 0.0, 0.0, 0.002, 0.01]))
            samples[name] = OffsetSample(now - age, bool(rng.random() < 0.9 if k % 1000 < 700 else rng.random() < 0.05), x)
        total, faults = fast.update(now, samples)
        total_ref, faults_ref = ref.update(now, samples)
        assert same(total, total_ref) and total.shape == (6,) and faults == faults_ref
        assert fast.alpha == ref.alpha
        n_faults += len(faults)
    assert n_faults > 100                    # (the faults were exercised)


def reference_payload_wrench(robot, x, xdot, xddot, mass, cog=(0.0, 0.0, 0.0)):
    """load_compensation.payload_wrench as it was: one function of set-point, cog and mass."""
    phi_x, phi_y, phi_z = np.asarray(x, dtype=float)[3:].tolist()
    cx, cy, cz = lcm._rotate(phi_x, phi_y, phi_z, *np.asarray(cog, dtype=float).tolist())
    wx, wy, wz = np.asarray(xdot, dtype=float)[3:].tolist()
    ax, ay, az, dwx, dwy, dwz = np.asarray(xddot, dtype=float).tolist()
    vx, vy, vz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
    a = (ax + dwy * cz - dwz * cy + wy * vz - wz * vy,
         ay + dwz * cx - dwx * cz + wz * vx - wx * vz,
         az + dwx * cy - dwy * cx + wx * vy - wy * vx)
    gx, gy, gz = robot.gravity.tolist()
    fx, fy, fz = mass * (gx - a[0]), mass * (gy - a[1]), mass * (gz - a[2])
    return np.array([fx, fy, fz, cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx])


@pytest.mark.parametrize("name", ["ipanema3_mini", "ipanema3"])
def test_payload_wrench_split_at_the_mass_is_the_reference(name):
    """payload_wrench = payload_wrench_of_mass(payload_kinematics(...), m), and the kinematics kept
    over a set-point with masses changing every period give the reference's wrench, bit for bit."""
    robot = load_robot(name)
    rng = np.random.default_rng(7)
    for _ in range(300):
        x, xdot, xddot = rng.normal(0.0, 0.3, 6), rng.normal(0.0, 0.5, 6), rng.normal(0.0, 2.0, 6)
        x[rng.random(6) < 0.2] = -0.0
        xdot[rng.random(6) < 0.3] = 0.0
        cog = (0.0, 0.0, 0.0) if rng.random() < 0.3 else tuple(rng.normal(0.0, 0.05, 3).tolist())
        kinematics = lcm.payload_kinematics(robot, x, xdot, xddot, cog)
        for mass in (*rng.normal(3.0, 2.0, 5).tolist(), 0.0, -0.0, np.float64(1.25), 2):
            ref = reference_payload_wrench(robot, x, xdot, xddot, mass, cog)
            assert same(lcm.payload_wrench(robot, x, xdot, xddot, mass, cog), ref)
            assert same(lcm.payload_wrench_of_mass(kinematics, mass), ref)


@pytest.mark.parametrize("seed", range(6))
def test_force_watch_period_compiled_is_its_reference_bit_for_bit(seed):
    """kernels.force_watch_period against control.safety's Python-float reference over 400 periods
    of random forces that leave the band and jump (fast rates), with and without f_d, m = 4 or 8:
    the same state (run counters, rates, rates away from f_d, last forces) and summary each period,
    and the same refusal (state untouched) of a non-finite period."""
    from cdpr_control import kernels
    from cdpr_control.control.safety import _force_watch_period
    rng = np.random.default_rng(seed)
    m = 4 if seed % 2 else 8
    has_f_d = seed % 3 != 0
    f_min, f_max = rng.uniform(1.0, 10.0, m), rng.uniform(30.0, 60.0, m)
    tol = 0.05 * (f_max - f_min)
    bounds = np.array([f_min - tol, f_max + tol, 20.0 * (f_max - f_min)])
    f0 = rng.uniform(f_min, f_max)
    states = [np.zeros((4, m)) for _ in range(2)]
    for s in states:
        s[3] = f0
    outs = [np.empty(5), np.empty(5)]
    for k in range(400):
        f = rng.uniform(f_min - 3 * tol, f_max + 3 * tol) if k % 7 else f0 + rng.normal(0.0, 0.01, m)
        f_d = np.round(rng.uniform(f_min, f_max), 1) if has_f_d else f
        if k % 5 == 0 and has_f_d:
            f_d[0] = f[0]                                     # f = f_d: no rate away
        if k % 97 == 13:
            f[rng.integers(m)] = np.nan if k % 2 else np.inf
        results = [law(f, f_d, has_f_d, bounds, s, 0.2, 1e3, o)
                   for law, s, o in ((kernels.force_watch_period, states[0], outs[0]),
                                     (_force_watch_period, states[1], outs[1]))]
        assert results[0] == results[1] == bool(np.isfinite(f).all()), k
        assert same(states[0], states[1]), k
        if results[0]:
            assert same(outs[0], outs[1]), k
