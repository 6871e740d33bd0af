"""The payload cases with the cable settlement identified on their plant (cdpr_tools.validate.settlement,
cause A of docs/validation.md "Payload after session 13"), and IK-only + LC refused before the force
watch's hold where IK-only control cannot carry the payload (cases.ik_only_payload_slack)."""
from dataclasses import replace

import numpy as np
import pytest

from cdpr_control.model.robot import load_robot
from cdpr_tools.validate import cases, settlement
from cdpr_tools.validate.cases import CaseSpec


def _loaded_run(robot, forces, dip=None):
    """A reference recorder at rest through the rest and 0.5 s of the step with the cable forces
    ``forces`` (m,), and ``dip`` (cable, force, start [s], duration [s])."""
    t = np.arange(1, int((cases.PAYLOAD_REST + 0.5) * 1000) + 1) * 1e-3
    f = np.tile(np.asarray(forces, dtype=float), (len(t), 1))
    if dip is not None:
        cable, force, start, duration = dip
        f[(t > start) & (t <= start + duration), cable] = force
    rec = cases.Recorder(robot)
    rec.rows.update(t=list(t), x=list(np.zeros((len(t), 6))), f=list(f))
    return rec


@pytest.mark.parametrize("dip, refused", [
    ((4, 2.5, 0.8, 0.060), True),      # 60 ms below the watch's edge (3.25 N) under the payload: the watch holds
    ((4, 2.5, 0.8, 0.040), False),     # 40 ms: within the watch's 50 ms
    ((4, 3.5, 0.8, 0.500), False),     # below f_min but within the watch's band
    ((4, 2.5, 0.1, 0.060), False),     # before the payload: ik_only_slack's ground, not this one
])
def test_ik_lc_is_refused_where_the_ik_only_reference_trips_the_watch_under_the_payload(dip, refused):
    """The Mini (f_min 5 N, the watch's edge 3.25 N, 50 ms): a cable of the IK-only reference below
    the edge for longer than the watch allows after the payload's step refuses ik_lc, with the cable,
    its force and "force control" named; shorter or shallower dips, or one before the step, do not."""
    robot = load_robot("ipanema3_mini")
    reason = cases.ik_only_payload_slack(robot, _loaded_run(robot, np.full(8, 8.0), dip), 1.5)
    if refused:
        assert "cable 5 falls to 2.5 N" in reason and "1.5 kg" in reason and "force control" in reason
    else:
        assert reason is None


@pytest.mark.parametrize("robot_name, reference, why", [
    # the Mini's cable 5 below the watch's edge for 100 ms under the payload (ik_only_payload_slack)
    ("ipanema3_mini", lambda robot: _loaded_run(robot, np.full(8, 8.0), (4, 2.0, 0.9, 0.1)), ("cannot carry", "cable 5")),
    # the IPAnema 3 on four taut cables for 90 % of the dwell (ik_only_payload_unconstrained)
    ("ipanema3", lambda robot: _dwell_run(robot, 4, 0.9), ("does not constrain the platform", "median 4 of 8")),
])
def test_payload_case_refuses_ik_lc_and_still_runs_force_control(monkeypatch, robot_name, reference, why):
    robot = load_robot(robot_name)
    run = reference(robot)
    monkeypatch.setattr(cases, "_payload_run", lambda spec, robot_, config, mass, **_: (run, np.zeros(0), True, None))
    ran = []
    monkeypatch.setattr(cases, "_payload_result",
                        lambda s, robot_, mass, base, sag_reference, note: ran.append(s.variant["controller"]) or "run")
    spec = CaseSpec("payload", robot_name, 0, list(robot.home), False, "mismatched", 1, {"fraction": 0.5})
    out = cases.payload_case(spec)
    assert ran == ["force_control"] and out[0] == "run"
    assert out[1].status == "refused" and out[1].spec.variant["controller"] == "ik_lc"
    assert all(w in out[1].note for w in why)


def test_shipped_settlement_record_leaves_the_parameter_file():
    assert settlement.lc_values(settlement.shipped()) == {}
    record = {"source": "identified", "settlement_ratio": 0.3, "settlement_time": 2.5}
    assert settlement.lc_values(record) == {"settlement_ratio": 0.3, "settlement_time": 2.5,
                                            "settlement_identified": True}


def test_identified_settlement_takes_cause_a_out_of_the_force_control_sag(tmp_path):
    """ipanema3 #8 of the 40-pose grid on the mismatched plant seed 1, 100 % of its dynamic capacity
    (35.7 kg) under force control: with the parameter file's settlement model (not in the pose) the
    forward kinematics misses about 2 mm of the sag (the plant's settlement: cause A); with the
    settlement identified on the plant first (as a user does, `cdpr identify settlement`) the unseen
    part is below 0.5 mm and the case passes. (The shipped run's cut, 81.6 % in session 12's sweep,
    is 90.7 % since the plant no longer settles from force control's start-up, cases.settle_plant;
    the identified run's 86.7 %: with the printed (3.19) the integral's offset above the set-point
    is what cause A had cancelled, docs/validation.md "Payload after session 13".)"""
    from cdpr_tools.validate.grid import sweep_poses

    robot = load_robot("ipanema3")
    pose = sweep_poses(robot, 40)[8]
    spec = CaseSpec("payload", "ipanema3", 8, list(pose.x), pose.border, "mismatched", 1,
                    {"fraction": 1.0, "controller": "force_control"})
    mass = cases.dynamic_capacity(robot, spec.x)
    reference, _, ok, _ = cases._payload_run(spec, robot, cases.REFERENCE, mass)
    assert ok and cases.ik_only_slack(robot, reference) is not None     # judged against (4.5)-(4.6)
    record, reused = settlement.identified(tmp_path, "ipanema3", "mismatched", 1)
    assert not reused and 0.2 < record["settlement_ratio"] < 0.6      # the plant's 0.3 of its own k0
    shipped = cases._payload_result(spec, robot, mass, {}, None, "")
    identified = cases._payload_result(replace(spec, settlement=record), robot, mass, {}, None, "")
    assert shipped.metrics["sag_unseen_mm"] < -1.5
    assert abs(identified.metrics["sag_unseen_mm"]) < 0.5
    assert identified.status == "passed", identified.note
    assert settlement.identified(tmp_path, "ipanema3", "mismatched", 1)[1]           # reused


def _settling_plant(robot, f_power_on, f, periods):
    """The simulator's settlement (cdpr_sim.plant.Settlement, ratio 0.3, T 2 s as plants/mismatch.yaml)
    settled to f_power_on and run ``periods`` of 1 ms at the forces f, at home, as a stand-in for the
    simulator that cases.settle_plant reads (its settlement, true forces, drive lengths and robot)."""
    from types import SimpleNamespace

    from cdpr_control.model import cable
    from cdpr_control.model.kinematics import inverse_kinematics
    from cdpr_sim.plant import Settlement

    st = Settlement(0.3, 2.0, robot.cable.k0, 1e-3, robot.m)
    theta = inverse_kinematics(robot, robot.home).q
    st.reset(f_power_on)
    sim = SimpleNamespace(settlement=st, output=SimpleNamespace(f=np.asarray(f, dtype=float)),
                          drives=SimpleNamespace(theta=theta), robot=robot)

    def run(periods):
        for _ in range(periods):
            st.update(sim.output.f, cable.total_free_length(robot, theta + st.s))
    run(periods)
    return sim, run


def test_settle_plant_ends_the_start_up_settlement_and_keeps_the_payloads():
    """cases.settle_plant: a plant that settles from its power-on forces under a raised pre-tension
    (force control's start-up) keeps its growth s but grows no further at the present forces (without
    it, s goes on towards ratio l_t df / k0 with T); a later force rise df settles by the law's closed
    form ratio l_t df / k0 on top of s, on every cable, also one whose force had dropped below its
    power-on force (settled to the present state)."""
    from cdpr_control.model import cable

    robot = load_robot("ipanema3_mini")
    f0 = np.full(robot.m, 10.0)
    pretension = np.array([8.0, 12.0, 3.0, 0.0, 8.0, 12.0, 3.0, -5.0])    # the start-up's rise [N]
    sim, run = _settling_plant(robot, f0, f0 + pretension, 400)             # 0.4 s of the start-up
    st = sim.settlement
    s_rest = st.s.copy()
    assert np.all(s_rest[pretension > 0] > 1e-6) and np.all(s_rest[pretension <= 0] == 0.0)
    unsettled, run_unsettled = _settling_plant(robot, f0, f0 + pretension, 400)
    run_unsettled(4000)
    assert np.all(unsettled.settlement.s[pretension > 0] - s_rest[pretension > 0] > 2e-5)   # the creep it ends

    cases.settle_plant(sim)
    np.testing.assert_array_equal(st.s, s_rest)                             # no jump
    run(4000)                                                               # 4 s at the rest's forces
    np.testing.assert_allclose(st.s, s_rest, rtol=0.0, atol=1e-12)

    df = 1.0                                                                # a payload's rise on every cable
    sim.output.f = f0 + pretension + df
    run(20000)                                                              # 10 T
    l_t = cable.total_free_length(robot, sim.drives.theta + st.s)
    np.testing.assert_allclose(st.s, s_rest + 0.3 * l_t * df / robot.cable.k0, rtol=1e-3)


def test_settle_plant_leaves_a_plant_without_settlement():
    robot = load_robot("ipanema3_mini")
    sim, _ = _settling_plant(robot, np.full(robot.m, 10.0), np.full(robot.m, 12.0), 10)
    sim.settlement.ratio = 0.0
    before = sim.settlement.f_settled.copy()
    cases.settle_plant(sim)
    np.testing.assert_array_equal(sim.settlement.f_settled, before)


def test_the_mini_at_rest_drifts_no_longer_by_the_plants_start_up_settlement():
    """Mini #1 of the 40-pose grid, mismatched plant seed 2, force control (shipped), no payload: the
    plant's cables settle by at most a few µm (by 66-382 µm under force control's start-up
    pre-tension without cases.settle_plant: docs/validation.md, "The Mini's sag after session 15"),
    and the platform's drift over the dwell is within its static accuracy."""
    from cdpr_tools.validate.grid import sweep_poses

    robot = load_robot("ipanema3_mini")
    pose = sweep_poses(robot, 40)[1]
    spec = CaseSpec("payload", "ipanema3_mini", 1, list(pose.x), pose.border, "mismatched", 2,
                    {"fraction": 0.5, "controller": "force_control"})
    rec, _, ok, hold = cases._payload_run(spec, robot, "force_control", 0.0)
    assert ok and hold is None
    # at most 1.5 µm (the forces of the dwell above the rest's end as the loop converges; without
    # settle_plant 66-382 µm per cable)
    assert np.abs(rec.settlement).max() < 3e-6, np.abs(rec.settlement).max(axis=0)
    assert abs(cases._sag(rec)) <= cases.static_accuracy(rec, float(spec.x[2]))


def _dwell_run(robot, taut, share):
    """A reference recorder from rest to 2 s after the step's end: every cable at 150 N but, over
    ``share`` of the periods from 1 s after the step began, the last m - ``taut`` at 0 N; in the
    first second after the step all but ``taut`` at 0 N (not judged: the sag and the swing's start)."""
    t = np.arange(1, int((cases.PAYLOAD_REST + cases.PAYLOAD_RAMP + 2.0) * 1000) + 1) * 1e-3
    f = np.full((len(t), robot.m), 150.0)
    window = np.flatnonzero(t >= cases.PAYLOAD_REST + 1.0)
    f[window[: int(share * len(window))], taut:] = 0.0
    f[(t > cases.PAYLOAD_REST) & (t < cases.PAYLOAD_REST + 1.0), 4:] = 0.0
    rec = cases.Recorder(robot)
    rec.rows.update(t=list(t), x=list(np.zeros((len(t), 6))), f=list(f))
    return rec


@pytest.mark.parametrize("taut, share, refused", [
    (5, 0.6, True),      # five taut cables for most of the dwell: a mechanism
    (4, 0.95, True),
    (5, 0.4, False),     # for less than half of it
    (6, 1.0, False),     # six taut cables fix the pose
])
def test_ik_lc_is_refused_where_ik_only_leaves_fewer_than_six_cables_taut_for_most_of_the_dwell(taut, share, refused):
    robot = load_robot("ipanema3")
    reason = cases.ik_only_payload_unconstrained(robot, _dwell_run(robot, taut, share), 115.7)
    if refused:
        assert f"{100 * share:.0f} % of the dwell" in reason and f"median {taut} of 8" in reason
        assert "116 kg" in reason and "force control" in reason and ">= 20 N" in reason
    else:
        assert reason is None
