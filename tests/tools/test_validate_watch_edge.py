"""The validation's IK-only slack checks (cases.ik_only_payload_slack, cases.ik_only_slack) judge
against the force watch's own lower edge (control.safety.watch_edges), not a copy of it: on the Mini
(f 5..40 N, force_band 0.05) 3.25 N."""
import numpy as np

from cdpr_control.control.params import control_loop_params
from cdpr_control.control.safety import watch_edges
from cdpr_control.model.robot import load_robot
from cdpr_tools.validate import cases

ROBOT = load_robot("ipanema3_mini")


def _run(duration, forces, dip=None):
    """A reference recorder at rest for ``duration`` s with the cable forces ``forces`` (m,), and
    ``dip`` (cable, force, start [s], length [s])."""
    t = np.arange(1, int(duration * 1000) + 1) * 1e-3
    f = np.tile(np.asarray(forces, dtype=float), (len(t), 1))
    if dip is not None:
        cable, force, start, length = dip
        f[(t > start) & (t <= start + length), cable] = force
    rec = cases.Recorder(ROBOT)
    rec.rows.update(t=list(t), x=list(np.zeros((len(t), 6))), f=list(f))
    return rec


def test_the_edge_is_the_watchs():
    c = ROBOT.cable
    safety = control_loop_params(ROBOT).safety
    edge = watch_edges(safety, c.f_min, c.f_max)[2]
    np.testing.assert_allclose(edge, c.f_min - safety.force_band * (c.f_max - c.f_min))
    np.testing.assert_allclose(edge, 3.25)


def test_a_slack_cable_under_the_payload_refuses_ik_lc():
    """0 N for 60 ms after the step: refused, naming the cable and the 3.25 N edge; 3 N (below the
    edge) for 40 ms, or 3.5 N (above it) for 0.5 s, are not."""
    rest, forces = cases.PAYLOAD_REST, np.full(ROBOT.m, 12.0)
    reason = cases.ik_only_payload_slack(ROBOT, _run(rest + 0.5, forces, (2, 0.0, rest + 0.1, 0.060)), 1.0)
    assert reason is not None and "cable 3 falls to 0 N" in reason and "edge 3.25 N" in reason
    assert cases.ik_only_payload_slack(ROBOT, _run(rest + 0.5, forces, (2, 3.0, rest + 0.1, 0.040)), 1.0) is None
    assert cases.ik_only_payload_slack(ROBOT, _run(rest + 0.5, forces, (2, 3.5, rest + 0.1, 0.5)), 1.0) is None


def test_a_slack_cable_before_the_payload_is_reported():
    rest, forces = cases.PAYLOAD_REST, np.full(ROBOT.m, 12.0)
    reason = cases.ik_only_slack(ROBOT, _run(rest, forces, (6, 3.0, 0.1, 0.060)))
    assert reason is not None and "cable(s) 7 (3.0 N)" in reason and "edge 3.2 N" in reason
    assert cases.ik_only_slack(ROBOT, _run(rest, forces, (6, 3.5, 0.1, 0.060))) is None
