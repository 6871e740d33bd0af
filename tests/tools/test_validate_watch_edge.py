"""The validation's IK-only slack checks (cases.ik_only_payload_slack, cases.ik_only_slack) judge
against the force watch's own lower edge (control.safety.watch_edges), not a copy of it: on the
IPAnema 3 (f 100..3000 N) that edge is 50 N (0.5 f_min), where force_band alone gave -45 N, which
no slack cable reaches."""
import numpy as np

from cdpr_control.control.params import control_loop_params
from cdpr_control.control.safety import watch_edges
from cdpr_control.model.robot import load_robot
from cdpr_tools.validate import cases

ROBOT = load_robot("ipanema3")


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
    edge = watch_edges(control_loop_params(ROBOT).safety, c.f_min, c.f_max)[2]
    np.testing.assert_allclose(edge, 50.0)


def test_a_slack_ipanema3_cable_under_the_payload_refuses_ik_lc():
    """0 N for 60 ms after the step (slack): refused, naming the cable and the 50 N edge; 40 N (below
    the edge) for 40 ms, or 60 N (above it) for 0.5 s, are not (the old edge -45 N refused neither)."""
    rest, forces = cases.PAYLOAD_REST, np.full(ROBOT.m, 800.0)
    reason = cases.ik_only_payload_slack(ROBOT, _run(rest + 0.5, forces, (2, 0.0, rest + 0.1, 0.060)), 20.0)
    assert reason is not None and "cable 3 falls to 0 N" in reason and "edge 50 N" in reason
    assert cases.ik_only_payload_slack(ROBOT, _run(rest + 0.5, forces, (2, 40.0, rest + 0.1, 0.040)), 20.0) is None
    assert cases.ik_only_payload_slack(ROBOT, _run(rest + 0.5, forces, (2, 60.0, rest + 0.1, 0.5)), 20.0) is None


def test_a_slack_ipanema3_cable_before_the_payload_is_reported():
    rest, forces = cases.PAYLOAD_REST, np.full(ROBOT.m, 800.0)
    reason = cases.ik_only_slack(ROBOT, _run(rest, forces, (6, 30.0, 0.1, 0.060)))
    assert reason is not None and "cable(s) 7 (30.0 N)" in reason and "edge 50.0 N" in reason
    assert cases.ik_only_slack(ROBOT, _run(rest, forces, (6, 60.0, 0.1, 0.060))) is None
