"""Test-session environment: ROS 2 traffic stays on this machine, in a domain of its own."""
import json
import os
import random
from pathlib import Path

# Discovery only on localhost (no multicast leaves the machine), and a random domain so that
# concurrent test runs on one machine do not see each other's nodes.
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.Random(os.getpid()).randint(1, 100)))
SESSION_DOMAIN = int(os.environ["ROS_DOMAIN_ID"])
# `cdpr` commands called in a test discover the graph themselves unless the test starts the graph
# daemon (and stops it) itself: tests/tools/test_cli_daemon.py
os.environ.setdefault("CDPR_NO_DAEMON", "1")
# Generated message classes check the type of every field they are given (read when a message
# module is imported, so before any test imports one): a wrong type fails a test with a Python
# error instead of asserting in the C conversion and aborting the process (issue 28, exit 134).
os.environ.setdefault("ROS_PYTHON_CHECK_FIELDS", "1")


import pytest  # noqa: E402

from cdpr_tools.file_lock import claim_ros_domain as claim_domain, locked  # noqa: E402


_NEXT_DOMAIN = [SESSION_DOMAIN]


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
    process. A failed ``compute`` leaves nothing behind: the next process to ask tries again."""
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


# --- `make test`: the test files over one worker process per core (pytest-xdist, --dist loadfile) ---
# A test file runs whole in one worker, so its module-scoped fixtures (a launched graph, a
# simulation, a fit) run once and its ROS domain is its own (ros_domain_of_the_module). A worker
# takes the next file when it has two tests left, so a slow file started last would end the run
# alone: the files are handed out slowest first, by their seconds in the last run that ran them
# (pytest's cache, .pytest_cache; a run of part of a file counts that part) or, in a fresh clone,
# by FILE_SECONDS. The order changes how
# long the run takes, never what a test sees (each file has its own domain and fixtures).
FILE_SECONDS_KEY = "cdpr/file_seconds"
# seconds of the slowest files, idle 2-core machine, sequential (`pytest --durations=0`, summed per
# file); a file missing here counts as 0 s until a run has measured it
FILE_SECONDS = {}


def _file_of(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """Whole files, slowest first (above), for ``--dist loadfile`` (and plain ``-n``, whose
    test-by-test distribution would run a file's module fixtures once in every worker)."""
    if config.option.dist not in ("load", "loadfile"):
        return None
    from xdist.scheduler import LoadFileScheduling

    cache = getattr(config, "cache", None)   # None with -p no:cacheprovider
    seconds = {**FILE_SECONDS, **(cache.get(FILE_SECONDS_KEY, {}) if cache else {})}

    class SlowestFileFirst(LoadFileScheduling):
        ordered = False

        def _assign_work_unit(self, node):
            # the first assignment follows schedule() filling the work queue (one unit a file, in
            # the order of the collection): order it once. (The workers' collections stay as they
            # are: the scheduler sends each test as its index in them.)
            if not self.ordered:
                order = {f: (-seconds.get(f, 0.0), k) for k, f in enumerate(self.workqueue)}
                for f in sorted(self.workqueue, key=order.__getitem__):
                    self.workqueue.move_to_end(f)
                self.ordered = True
            super()._assign_work_unit(node)

    config.option.loadscopereorder = False   # keep the order above (not: most tests first)
    return SlowestFileFirst(config, log)


_SECONDS_THIS_RUN: dict[str, float] = {}


def pytest_runtest_logreport(report):
    """Each file's seconds in this run (setup, call and teardown of its tests): in a pytest-xdist
    run the controller process sees every worker's reports."""
    _SECONDS_THIS_RUN[_file_of(report.nodeid)] = _SECONDS_THIS_RUN.get(_file_of(report.nodeid), 0.0) + report.duration


def pytest_sessionfinish(session):
    """Store the files' seconds for the next run's order (the controller's, or a plain run's)."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config, "cache", None) or not _SECONDS_THIS_RUN:
        return
    stored = config.cache.get(FILE_SECONDS_KEY, {})
    config.cache.set(FILE_SECONDS_KEY, {**stored, **{f: round(s, 1) for f, s in _SECONDS_THIS_RUN.items()}})
