"""``cdpr demo`` says why a run failed though its program ended, and exits 1: the safety layer
held the robot (the joint command's holding fault on /diagnostics), or a cable force diverged."""
import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from cdpr_tools.bag import BagWriter
from cdpr_tools.demo_cmd import DIVERGENCE_FACTOR, holds, run_problems
from cdpr_tools.run_report import RunData

F_MAX = 40.0


def _data(f):
    n = len(f)
    return RunData(t=np.arange(n) * 1e-3, x_d=np.zeros((n, 6)), x=np.zeros((n, 6)), f=np.asarray(f, dtype=float),
                   f_min=np.full(2, 5.0), f_max=np.full(2, F_MAX), f_d=None, dq_cfc=None, x_ospc=None)


def _status(name, level, message, holding, abort):
    return DiagnosticStatus(level=level, name=name, message=message,
                            values=[KeyValue(key="holding", value=str(holding)), KeyValue(key="abort", value=str(abort))])


def test_a_run_within_the_limits_has_no_problem():
    assert run_problems(_data([[10.0, 20.0], [F_MAX, 30.0]]), []) == []


def test_a_force_beyond_the_divergence_factor_or_not_finite_is_a_divergence_with_its_time():
    (p,) = run_problems(_data([[10.0, 20.0], [10.0, 1.01 * DIVERGENCE_FACTOR * F_MAX], [10.0, 20.0]]), [])
    assert p.startswith("diverged") and "t = 0.001 s" in p and "60.6 N" in p
    (p,) = run_problems(_data([[10.0, 20.0], [10.0, 20.0], [np.nan, 20.0]]), [])
    assert "not finite at t = 0.002 s" in p


def test_a_latched_hold_of_the_joint_command_fails_the_run_with_its_message_a_transient_one_does_not(tmp_path):
    bag = tmp_path / "run"
    with BagWriter(bag) as w:
        for i, (name, holding, abort, message) in enumerate([
                ("/joint_command", False, False, "ok"),
                ("/cable_force_controller", True, True, "another node's value named holding"),
                ("/joint_command", True, False, "forward kinematics did not converge; holding"),
                ("/joint_command", True, True, "force watch: cable 3 above f_max for 51 ms; holding")]):
            header = Header(stamp=Time(sec=2, nanosec=i * 1_000_000))
            w.write("/diagnostics", None, DiagnosticArray(header=header, status=[
                _status(name, DiagnosticStatus.ERROR if holding else DiagnosticStatus.OK, message, holding, abort)]),
                (2_000_000 + i * 1_000) * 1_000)
    held, transient = holds(bag)
    assert held == ["t = 2.003 s: force watch: cable 3 above f_max for 51 ms; holding"]
    assert transient == ["t = 2.002 s: forward kinematics did not converge; holding"]
    (p,) = run_problems(_data([[10.0, 20.0]]), held)
    assert "the safety layer held the robot" in p and "force watch: cable 3" in p


def test_the_demo_waits_for_its_own_graph_to_take_the_program_as_long_as_the_program_may_run(tmp_path, monkeypatch):
    """The demo starts the graph itself, so the goal's answer (the interpreter plans and checks the
    program between the loop's periods) may take up to ``--timeout``, not the 30 s a client of a
    graph already running waits (a clean clone's `make demo` at a load of 25 failed on those 30 s)."""
    import types

    import cdpr_tools.launch
    import cdpr_tools.program_client
    from cdpr_tools import cli

    calls = []

    class Graph:
        errors = []

        def __init__(self, description, mode=None):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    def run_program(text, name, **kwargs):
        calls.append(kwargs)
        return types.SimpleNamespace(success=False, message="refused by the test", duration=0.0)

    monkeypatch.setattr(cdpr_tools.launch, "Launcher", Graph)
    monkeypatch.setattr(cdpr_tools.program_client, "run_program", run_program)
    assert cli.main(["demo", "--output", str(tmp_path / "bag"), "--timeout", "321"]) == 1
    assert [(c["timeout"], c["server_timeout"]) for c in calls] == [(321.0, 321.0)]
