"""The launcher: start a node graph from a launch description, composed or one process per node.

``launch``/``launch_ros`` are not on PyPI, so the project starts its graphs itself. A graph is a
list of nodes (a Python module following the node convention of docs/tools.md, or a console-script
entry point) with name, namespace, parameters (inline or standard parameter files) and
remappings. Every node gets the same ``--ros-args`` in both modes:

- ``composed``: one process, every node built with ``cli_args=<its ros args>`` in one context and
  spun by one executor; messages between the nodes are delivered in-process as Python objects
  (cdpr_control.ros.intraprocess) and over DDS only to subscribers outside the process
  (``intra_process=False``: DDS for everything on an ``EventsExecutor``, about 24 us a hop);
- ``processes``: one subprocess per node, ``main([module, --ros-args ...])``; DDS connects them, so
  they may as well run on other machines.

Optionally every topic is recorded to a bag meanwhile; composed, the recorder is one more node of
the graph and takes the in-process messages, serialized once each, and the graph is held (not spun)
until the recorder has subscribed to every topic it publishes, so a lockstep run is recorded from its
first period. ``stop()`` (Ctrl-C in ``cdpr launch``)
ends everything cleanly: executors stop, nodes are destroyed, children get SIGINT (then SIGTERM,
then SIGKILL if they hang), the bag is closed.
"""
from __future__ import annotations

import ctypes
import importlib
import importlib.metadata
import inspect
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path

import yaml
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from cdpr_tools.bag.recorder import BagRecorder, default_bag_name
from cdpr_control.ros.intraprocess import IntraProcess
from cdpr_control.ros.runner import spin
from cdpr_tools.ros_graph import _hidden_topic, keep_discovery_local, new_context

MODES = ("composed", "processes")
STOP_TIMEOUT = 10.0  # s a child may take to exit after SIGINT before it gets SIGTERM
# s an executor thread may take to end its callback after the stop; its nodes are destroyed after it
# ends (destroyed under a running callback, they raised InvalidHandle at shutdown on a loaded machine)
EXECUTOR_STOP_TIMEOUT = 30.0
RECORDER_TIMEOUT = 60.0  # s the recorder may take to discover a composed graph's topics
# child process: import the node module and call its main([module, --ros-args, ...])
# A child stopped while it still imports its node's module (SIGINT/SIGTERM before its main runs)
# has nothing to clean up yet: it ends at once with code 0 instead of a KeyboardInterrupt traceback
# (seen when a loaded machine is slow to start thirteen processes and the launch is stopped early).
_BOOTSTRAP = ("import os, signal, sys\n"
              "def _stopped_while_starting(*_):\n"
              "    os.write(1, b'stopped while starting\\n')\n"
              "    os._exit(0)\n"
              "signal.signal(signal.SIGINT, _stopped_while_starting)\n"
              "signal.signal(signal.SIGTERM, _stopped_while_starting)\n"
              "import importlib\n"
              "main = getattr(importlib.import_module(sys.argv[1]), sys.argv[2])\n"
              "signal.signal(signal.SIGINT, signal.default_int_handler)\n"   # main's own handling from here
              "signal.signal(signal.SIGTERM, signal.SIG_DFL)\n"
              "sys.exit(main([sys.argv[1]] + sys.argv[3:]))\n")


@dataclass
class NodeSpec:
    """One node of a graph; ``module`` (dotted path) or ``entry_point`` (console script name)."""
    module: str | None = None
    entry_point: str | None = None
    name: str | None = None  # node name; default: the one the class gives itself
    namespace: str | None = None
    parameters: list = field(default_factory=list)  # mappings (inline) and parameter file paths, in order
    remappings: dict = field(default_factory=dict)  # from -> to
    ros_args: list = field(default_factory=list)  # further --ros-args arguments, e.g. [--log-level, debug]
    required: bool = False  # its end (process exit) ends the whole launch

    def target(self) -> tuple[str, str]:
        """(module, main function name) to run."""
        if bool(self.module) == bool(self.entry_point):
            raise ValueError(f"node {self.label}: give exactly one of module or entry_point")
        if self.module:
            return self.module, "main"
        found = importlib.metadata.entry_points(group="console_scripts", name=self.entry_point)
        if not found:
            raise LookupError(f"node {self.label}: no console script {self.entry_point!r} is installed")
        module, _, func = next(iter(found)).value.partition(":")
        return module.strip(), (func.strip() or "main")

    @property
    def label(self) -> str:
        base = self.name or (self.module or self.entry_point or "?").rpartition(".")[2]
        return f"{(self.namespace or '').strip('/')}/{base}".lstrip("/")


@dataclass
class RecordSpec:
    """Record topics to a bag while the graph runs (see :class:`~cdpr_tools.bag.recorder.BagRecorder`)."""
    output: str | None = None
    topics: list = field(default_factory=list)  # empty: every topic
    exclude: str = ""
    include_hidden_topics: bool = False
    compression: str = "zstd"     # MCAP chunk compression: zstd, lz4 or none


@dataclass
class LaunchDescription:
    nodes: list
    mode: str = "composed"
    parameters: dict = field(default_factory=dict)  # given to every node first, e.g. {use_sim_time: true}
    record: RecordSpec | None = None
    source: Path | None = None  # the launch file, for messages and relative paths


# Launch files (ROS 2 YAML launch format) are read by cdpr_tools.launch_file.load_launch_file.


def select_nodes(description: LaunchDescription, only: list[str] | None = None,
                 exclude: list[str] | None = None) -> LaunchDescription:
    """The graph restricted to some nodes, to run the parts of one graph on several hosts/processes.

    A pattern (regular expression) selects a node when it matches its label (``ns/name``) or its
    module/entry point in full or as a dotted suffix, e.g. ``winch_platform_sim``.
    """
    def matches(spec: NodeSpec, patterns) -> bool:
        names = [spec.label, spec.module or spec.entry_point or ""]
        names += [n.rpartition(".")[2] for n in names]
        return any(re.fullmatch(p, n) for p in patterns for n in names)

    nodes = [n for n in description.nodes
             if (not only or matches(n, only)) and not (exclude and matches(n, exclude))]
    if not nodes:
        raise ValueError(f"no node of the graph is selected (only {only or '-'}, exclude {exclude or '-'}); "
                         f"nodes: {', '.join(n.label for n in description.nodes)}")
    return replace(description, nodes=nodes)


# -- the arguments every node gets ------------------------------------------------------------------
def ros_arguments(spec: NodeSpec, common: dict, tmpdir: Path) -> list[str]:
    """``--ros-args`` for one node: remaps, then parameters (common, then the node's, in order)."""
    args = ["--ros-args"]
    if spec.name:
        args += ["-r", f"__node:={spec.name}"]
    if spec.namespace:
        args += ["-r", f"__ns:=/{spec.namespace.strip('/')}"]
    for src, dst in spec.remappings.items():
        args += ["-r", f"{src}:={dst}"]
    for params in ([common] if common else []) + list(spec.parameters):
        if isinstance(params, dict):  # inline: through a parameter file, so YAML types carry over
            fd, name = tempfile.mkstemp(prefix="params_", suffix=".yaml", dir=tmpdir)
            with os.fdopen(fd, "w") as f:
                yaml.safe_dump({"/**": {"ros__parameters": params}}, f)
            params = name
        args += ["--params-file", str(params)]
    return args + list(spec.ros_args)


def node_class(module_name: str) -> type:
    """The node class a module defines (the one most-derived ``rclpy.node.Node`` subclass)."""
    module = importlib.import_module(module_name)
    classes = [c for c in vars(module).values()
               if inspect.isclass(c) and issubclass(c, Node) and c.__module__ == module.__name__]
    leaves = [c for c in classes if not any(o is not c and issubclass(o, c) for o in classes)]
    if len(leaves) != 1:
        found = ", ".join(c.__name__ for c in leaves) or "none"
        raise LookupError(f"module {module_name} must define exactly one node class (rclpy Node subclass); found {found}")
    return leaves[0]


# -- running --------------------------------------------------------------------------------------
class Launcher:
    """Start, watch and stop a graph.

    >>> with Launcher(load_launch_file("graph.yaml")) as launch:
    ...     launch.wait()            # until Ctrl-C, stop(), or the graph ends by itself
    """

    def __init__(self, description: LaunchDescription, mode: str | None = None, intra_process: bool = True,
                 stop_timeout: float = STOP_TIMEOUT):
        self.description = description
        # s a child may take to exit after SIGINT (ros2 launch's sigterm_timeout): a loaded machine
        # may need more than the default for a child that still builds its node or exits its interpreter
        self.stop_timeout = stop_timeout
        self.intra_process = intra_process  # composed: in-process delivery (False: DDS only, the old transport)
        self.mode = mode or description.mode
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        self.nodes: list[Node] = []  # composed mode: the node objects
        self.processes: dict[str, subprocess.Popen] = {}  # processes mode: label -> child
        self.recorder: BagRecorder | None = None
        self.errors: list[str] = []
        self._stop = threading.Event()
        # a recorder of its own spins until the graph's processes have ended: what they publish while
        # stopping is recorded too
        self._recorder_stop = threading.Event()
        self._done = threading.Event()
        self._threads: list[threading.Thread] = []
        self._contexts: list[Context] = []
        self._graph: tuple[Context, EventsExecutor] | None = None  # composed: the context and executor
        self._tmpdir = tempfile.TemporaryDirectory(prefix="cdpr_launch_")
        self._output_lock = threading.Lock()
        self._started = self._stopped = False

    def start(self) -> "Launcher":
        if self._started:
            raise RuntimeError("launcher already started")
        self._started = True
        keep_discovery_local()  # children inherit it
        try:
            if self.mode == "processes":
                self._start_processes()  # before any thread of ours: children fork from a quiet parent
            else:
                self._start_composed()
            if self.description.record is not None:
                self._start_recorder(self.description.record)
                if self.mode == "composed":
                    if self._threads[-1].name == "cdpr-launch-recorder":
                        self._threads[-1].start()  # the recorder spins, the graph waits for it
                    self._hold_until_recorded()
            for thread in self._threads:
                if thread.ident is None:
                    thread.start()
        except BaseException:
            self.stop()
            raise
        return self

    def _start_composed(self) -> None:
        context = self._new_context()
        IntraProcess.set_enabled(context, self.intra_process)
        # in-process, the loop's messages never reach the executor, which only runs timers, services
        # and DDS input. Lockstep: the SingleThreadedExecutor runs timers on time between the slices
        # of the endless in-process ring, where the EventsExecutor of these wheels delays them more
        # and more (10 Hz became 0.3 Hz). Free-running, each period is one timer event whose chain
        # ends within it, and a SingleThreadedExecutor turn (its wait set rebuilt over every entity,
        # about 1.6 ms) would cost more than the period: the EventsExecutor takes events off a queue.
        lockstep = self.description.parameters.get("sync_mode", "exact") == "exact"
        waits = self.intra_process and lockstep
        executor = (SingleThreadedExecutor if waits else EventsExecutor)(context=context)
        # a wait set rebuilt every turn: subscriptions without QoS event handlers (intraprocess.py)
        IntraProcess.of(context).subscription_events = not waits
        self._graph = context, executor
        for spec in self.description.nodes:
            module, _ = spec.target()
            cls = node_class(module)
            try:
                node = cls(context=context, cli_args=ros_arguments(spec, self.description.parameters,
                                                                    Path(self._tmpdir.name)))
            except Exception as exc:
                raise RuntimeError(f"node {spec.label} ({module}) failed to start: {exc}") from exc
            self.nodes.append(node)
            executor.add_node(node)
        self._threads.append(threading.Thread(target=self._run_executor, args=(executor, "graph"),
                                              name="cdpr-launch-graph", daemon=True))

    def _start_processes(self) -> None:
        # children import what the launcher can import (its sys.path), and print as they go
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), "PYTHONUNBUFFERED": "1"}
        for spec in self.description.nodes:
            module, func = spec.target()
            cmd = [sys.executable, "-c", _BOOTSTRAP, module, func,
                   *ros_arguments(spec, self.description.parameters, Path(self._tmpdir.name))]
            label = spec.label
            while label in self.processes:
                label += "'"
            self.processes[label] = subprocess.Popen(
                cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                text=True, errors="replace",
                start_new_session=True,  # Ctrl-C reaches the launcher only, which stops children in order
                preexec_fn=_die_with_parent)
        for (label, process), spec in zip(self.processes.items(), self.description.nodes):
            self._threads.append(threading.Thread(target=self._watch, args=(label, process, spec.required),
                                                  name=f"cdpr-launch-{label}", daemon=True))

    def _start_recorder(self, record: RecordSpec) -> None:
        in_graph = self._graph is not None and self.intra_process
        context = self._graph[0] if in_graph else self._new_context()
        overrides = [Parameter("output", value=record.output or default_bag_name()),
                     Parameter("exclude", value=record.exclude),
                     Parameter("include_hidden_topics", value=bool(record.include_hidden_topics)),
                     Parameter("compression", value=record.compression),
                     Parameter("use_sim_time", value=bool(self.description.parameters.get("use_sim_time", False)))]
        if record.topics:
            overrides.append(Parameter("topics", value=[str(t) for t in record.topics]))
        self.recorder = BagRecorder(context=context, parameter_overrides=overrides)
        if in_graph:  # a node of the composed graph: in-process messages, the graph's executor
            self._graph[1].add_node(self.recorder)
            return
        executor = EventsExecutor(context=context)
        executor.add_node(self.recorder)
        self._threads.append(threading.Thread(target=self._run_executor,
                                              args=(executor, "recorder", self._recorder_stop),
                                              name="cdpr-launch-recorder", daemon=True))

    def _hold_until_recorded(self, timeout: float = RECORDER_TIMEOUT) -> None:
        """Composed graph, not yet spun: wait until the recorder records every topic it publishes
        (a recorder in the graph's own executor discovers them from here, before that spins).

        DDS discovery takes up to seconds; a lockstep graph would meanwhile run its first periods
        unrecorded. Nothing of the graph runs before its executor spins, so holding it costs nothing.
        """
        topics = {p.topic_name for node in self.nodes for p in node.publishers}
        topics = {t for t in topics if self.recorder.selection.wanted(t) and not _hidden_topic(t)}
        deadline = time.monotonic() + timeout
        in_graph = not any(t.name == "cdpr-launch-recorder" for t in self._threads)
        while not topics <= set(self.recorder.recorded_topics):
            if in_graph:            # a node of the graph's executor, which does not spin yet: discover here
                self.recorder.selection.discover()
                if topics <= set(self.recorder.recorded_topics):
                    break
            if time.monotonic() > deadline:
                missing = sorted(topics - set(self.recorder.recorded_topics))
                raise TimeoutError(f"the recorder did not subscribe to {', '.join(missing)} within {timeout:g} s")
            time.sleep(0.05)

    def _new_context(self) -> Context:
        context = new_context()
        self._contexts.append(context)
        return context

    def _run_executor(self, executor, what: str, stop: threading.Event | None = None) -> None:
        try:
            spin(executor, stop or self._stop)
        except Exception as exc:  # a callback raised: report it and end the launch
            self._print(what, traceback.format_exc().rstrip())
            self.errors.append(f"{what}: {type(exc).__name__}: {exc}")
        finally:
            self._done.set()

    def _watch(self, label: str, process: subprocess.Popen, required: bool) -> None:
        for line in process.stdout:
            self._print(label, line.rstrip("\n"))
        code = process.wait()
        if not self._stop.is_set():
            self._print(label, f"process exited with code {code}")
            if code != 0:
                self.errors.append(f"{label}: exit code {code}")
        elif code != 0:
            self._print(label, f"exited with code {code} while stopping")
        if required or all(p.poll() is not None for p in self.processes.values()):
            self._done.set()

    def _print(self, label: str, text: str) -> None:
        with self._output_lock:
            for line in text.splitlines() or [""]:
                print(f"[{label}] {line}", flush=True)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until the graph ends by itself or :meth:`stop` is called; False on timeout."""
        return self._done.wait(timeout)

    def stop(self, timeout: float | None = None) -> None:
        """Stop everything cleanly (idempotent); children that ignore SIGINT for ``timeout`` (default:
        ``stop_timeout``) get SIGTERM, then SIGKILL."""
        timeout = self.stop_timeout if timeout is None else timeout
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        stop_flag = time.monotonic()
        for process in self.processes.values():
            _signal(process, signal.SIGINT)
        for sig in (signal.SIGTERM, signal.SIGKILL):
            for label, process in self.processes.items():
                try:
                    process.wait(timeout)
                except subprocess.TimeoutExpired:
                    self._print(label, f"did not stop within {timeout:g} s, sending {sig.name}")
                    _signal(process, sig)
            timeout = 3.0
        self._recorder_stop.set()
        executors = {t.name: t for t in self._threads if t.name in ("cdpr-launch-graph", "cdpr-launch-recorder")}
        for thread in self._threads:
            if thread.is_alive():
                thread.join(max(0.0, stop_flag + EXECUTOR_STOP_TIMEOUT - time.monotonic())
                            if thread.name in executors else timeout)
        busy = {name for name, thread in executors.items() if thread.is_alive()}
        for name in sorted(busy):   # a callback that does not end: its nodes stay as they are until exit
            self._print(name.removeprefix("cdpr-launch-"), f"still in a callback {EXECUTOR_STOP_TIMEOUT:g} s after "
                        "the stop; its nodes are left to the process's exit")
        if "cdpr-launch-graph" not in busy:
            for node in self.nodes:
                node.destroy_node()
        recorder_thread = "cdpr-launch-recorder" if "cdpr-launch-recorder" in executors else "cdpr-launch-graph"
        if self.recorder is not None and recorder_thread not in busy:
            self.recorder.destroy_node()
        if not busy:
            for context in self._contexts:
                context.try_shutdown()
        self._tmpdir.cleanup()
        self._done.set()

    @property
    def exit_codes(self) -> dict[str, int | None]:
        return {label: p.poll() for label, p in self.processes.items()}

    def __enter__(self) -> "Launcher":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _signal(process: subprocess.Popen, sig: signal.Signals) -> None:
    if process.poll() is None:
        try:
            process.send_signal(sig)
        except ProcessLookupError:
            pass


_PR_SET_PDEATHSIG = 1
_libc = ctypes.CDLL(None, use_errno=True) if sys.platform.startswith("linux") else None


def _die_with_parent() -> None:
    """In the child before exec: get SIGTERM if the launcher dies, so no node outlives it.

    (Linux delivers it when the thread that started the child ends: start from the main thread.)
    """
    if _libc is not None:
        _libc.prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
