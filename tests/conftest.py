"""Test-session environment: ROS 2 traffic stays on this machine, in a domain of its own."""
import json
import os
import random
from pathlib import Path

from cdpr_tools.file_lock import claim_ros_domain as claim_domain, locked  # noqa: E402

# Discovery only on localhost (no multicast leaves the machine), and a domain of the session's own
# (held like a module's, below) so that concurrent test runs on one machine, and the other worker
# processes of this one, do not see each other's nodes: what runs outside a module's domain (a
# session fixture such as the friction run, set up before the module's) uses it, and no module of
# another worker may claim it meanwhile (an unclaimed session domain let another worker's graph
# share it).
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
# (A pytest-xdist worker inherits the controller's environment: it claims a session domain of its
# own unless the user chose ROS_DOMAIN_ID.)
_SESSION_LOCK = None
if "ROS_DOMAIN_ID" not in os.environ or (
        os.environ.get("PYTEST_XDIST_WORKER")
        and os.environ.get("CDPR_TEST_SESSION_DOMAIN") == os.environ["ROS_DOMAIN_ID"]):
    _domain, _SESSION_LOCK = claim_domain(random.Random(os.getpid()).randint(1, 100))
    os.environ["ROS_DOMAIN_ID"] = os.environ["CDPR_TEST_SESSION_DOMAIN"] = str(_domain)
SESSION_DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
# `cdpr` commands called in a test discover the graph themselves unless the test starts the graph
# daemon (and stops it) itself: tests/tools/test_cli_daemon.py
os.environ.setdefault("CDPR_NO_DAEMON", "1")
# Generated message classes check the type of every field they are given (read when a message
# module is imported, so before any test imports one): a wrong type fails a test with a Python
# error instead of asserting in the C conversion and aborting the process (issue 28, exit 134).
os.environ.setdefault("ROS_PYTHON_CHECK_FIELDS", "1")


import pytest  # noqa: E402


_NEXT_DOMAIN = [SESSION_DOMAIN % 100 + 1]


@pytest.fixture(scope="session", autouse=True)
def ros_logging_held_for_the_session():
    """rclpy configures the process's logging (rcl_logging_configure) when the first context of the
    process starts, and finalises it (rcl_logging_fini) when the last one shuts down. A test process
    starts and shuts down hundreds of contexts one after the other, so it finalised and configured
    logging hundreds of times, each time with DDS threads of earlier contexts possibly still winding
    down. One `make test` (session 22) hung in that finalisation, in a fixture's teardown
    (Context.try_shutdown -> Context._logging_fini, the worker's only other thread execnet's).
    A context of the session's own, started here and never shut down, keeps logging configured from
    the first test to the session's end: no test's teardown finalises it. It creates no node, so
    no DDS participant (rmw_fastrtps makes one with a context's first node)."""
    from rclpy.context import Context

    context = Context()
    context.init(args=[])
    yield context


@pytest.fixture(scope="module", autouse=True)
def ros_domain_of_the_module():
    """Each test module on a ROS domain of its own: whatever an earlier module left publishing (a
    node of a failed test, a player) cannot reach this module's subscribers or recordings, nor can
    a module of another test session running on the same machine (:func:`claim_domain`). The
    domains cycle from the session's random one through 1..100 (FastDDS's port range on localhost);
    contexts, launched graphs and subprocesses made in the module read ROS_DOMAIN_ID when they start.
    Autouse at module scope: set before the module's other fixtures start anything."""
    domain, lock = claim_domain(_NEXT_DOMAIN[0])
    _NEXT_DOMAIN[0] = domain % 100 + 1
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    try:
        yield domain
    finally:
        os.environ["ROS_DOMAIN_ID"] = str(SESSION_DOMAIN)
        lock.close()


def session_directory(tmp_path_factory, name: str) -> Path:
    """A directory of this test session that every one of its processes shares: with pytest-xdist
    (`make test`) each worker has a temporary directory of its own under the session's, so a
    session-scoped result that several test files need (and which those files' workers would each
    compute) is made once in the session's and read by the others (:func:`computed_once`)."""
    base = tmp_path_factory.getbasetemp()
    directory = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / name
    directory.mkdir(parents=True, exist_ok=True)
    return directory


def computed_once(directory: Path, compute):
    """``compute()`` (a JSON value) run by the first process of the session that asks for it while
    the others wait on the directory's lock, then read from ``directory``/result.json by every
    process. A failed ``compute`` writes no result.json: the next process to ask runs it again
    (on whatever the failed one left in ``directory``), so each of them reports the failure."""
    result = directory / "result.json"
    with locked(directory / ".lock"):
        if not result.exists():
            value = compute()
            result.with_suffix(".tmp").write_text(json.dumps(value))
            result.with_suffix(".tmp").rename(result)
    return json.loads(result.read_text())


@pytest.fixture(scope="session")
def friction_bag(tmp_path_factory):
    """A short friction identification run of the IPAnema 3 Mini (section 3.7.2 trajectory: a few
    seconds of stop-and-go and alternating moves, then faster ones), recorded once per session (once
    for all the session's worker processes)."""
    from cdpr_tools.identify import experiments

    directory = session_directory(tmp_path_factory, "identification")
    return Path(computed_once(directory, lambda: str(experiments.record_friction_run(
        directory / "friction", "ipanema3_mini", seed=3,
        amplitudes=(0.0005, 0.002, 0.005), pause=0.05, fast_amplitude=0.01, fast_velocities=(0.2, 0.4)))))


@pytest.fixture(scope="session")
def identified_friction(friction_bag, tmp_path_factory):
    """``cdpr identify friction BAG -o friction.yaml --plot fit.png`` on the session's friction run,
    run once (the fit of 8 cables takes about 10 s; once for all the session's worker processes):
    tests/tools/test_identify.py asserts on its exit status, output and files,
    tests/model/test_friction_hysteresis.py loads its parameter file."""
    import contextlib
    import io
    from types import SimpleNamespace

    from cdpr_tools import cli

    directory = session_directory(tmp_path_factory, "identified_friction")
    params, plot = directory / "friction.yaml", directory / "fit.png"

    def identify():
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            code = cli.main(["identify", "friction", str(friction_bag), "-o", str(params), "--plot", str(plot)])
        return {"code": code, "out": out.getvalue()}

    run = computed_once(directory, identify)
    return SimpleNamespace(code=run["code"], out=run["out"], params=params, plot=plot)


@pytest.fixture(scope="module", params=("ipanema3_mini", "ipanema3"))
def robot(request):
    """Each shipped robot (thesis tables 2.1-2.4) with the compiled kernels loaded for it, for the
    tests that hold on both; a module with a robot of its own defines its own ``robot``."""
    from cdpr_control import kernels
    from cdpr_control.model.robot import load_robot

    robot = load_robot(request.param)
    kernels.warm_up(robot)
    return robot
