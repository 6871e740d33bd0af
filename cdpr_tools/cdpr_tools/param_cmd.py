"""``cdpr param list|get|set|describe|dump|load``: node parameters through the standard services.

The commands call ``<node>/list_parameters``, ``get_parameters``, ``set_parameters`` and
``describe_parameters`` (rcl_interfaces), as ``ros2 param`` does, so they work on any ROS 2 node
and ``ros2 param`` works on ours. ``dump`` prints (``load`` reads) the standard parameter file
layout ``/node: {ros__parameters: {...}}``. ``list``, ``get``, ``set``, ``describe`` and ``dump``
(to the terminal) run in the graph daemon, which keeps the graph and each node's parameter
clients (``cdpr daemon``); ``--no-daemon`` or CDPR_NO_DAEMON=1 runs them here.
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import yaml
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rclpy.parameter import Parameter, get_parameter_value, parameter_value_to_python

from cdpr_control.analysis.arguments import non_negative, positive
from cdpr_tools.daemon.client import add_no_daemon
from cdpr_control.model.yaml_file import load_yaml
from cdpr_tools.ros_graph import (
    DISCOVERY_TIMEOUT,
    find_node,
    graph_node,
    node_names,
    parameter_client,
    settle,
    spin_future,
    spin_until,
)

_TYPE_NAMES = {
    ParameterType.PARAMETER_NOT_SET: "not set", ParameterType.PARAMETER_BOOL: "boolean",
    ParameterType.PARAMETER_INTEGER: "integer", ParameterType.PARAMETER_DOUBLE: "double",
    ParameterType.PARAMETER_STRING: "string", ParameterType.PARAMETER_BYTE_ARRAY: "byte array",
    ParameterType.PARAMETER_BOOL_ARRAY: "boolean array", ParameterType.PARAMETER_INTEGER_ARRAY: "integer array",
    ParameterType.PARAMETER_DOUBLE_ARRAY: "double array", ParameterType.PARAMETER_STRING_ARRAY: "string array",
}
# how `ros2 param get` introduces a value of each type
_GET_LABELS = {
    ParameterType.PARAMETER_BOOL: "Boolean value is", ParameterType.PARAMETER_INTEGER: "Integer value is",
    ParameterType.PARAMETER_DOUBLE: "Double value is", ParameterType.PARAMETER_STRING: "String value is",
    ParameterType.PARAMETER_BYTE_ARRAY: "Byte values are", ParameterType.PARAMETER_BOOL_ARRAY: "Boolean values are",
    ParameterType.PARAMETER_INTEGER_ARRAY: "Integer values are",
    ParameterType.PARAMETER_DOUBLE_ARRAY: "Double values are", ParameterType.PARAMETER_STRING_ARRAY: "String values are",
}


_NEGATIVE_VALUE = re.compile(r"^-(\d+|\d*\.\d*([eE][-+]?\d+)?|\d+[eE][-+]?\d+|\.?(inf|Inf|INF)|\.?(nan|NaN|NAN))$")
_INT64 = (-(1 << 63), (1 << 63) - 1)


def add_parser(sub) -> None:
    p = sub.add_parser("param", help="list, get, set, describe, dump and load node parameters",
                       description=__doc__.replace("``", ""), formatter_class=argparse.RawDescriptionHelpFormatter)
    verbs = p.add_subparsers(dest="verb", metavar="VERB", required=True)

    ls = verbs.add_parser("list", help="parameter names of one node or of every node")
    ls.add_argument("node", nargs="?", help="node name (default: every node)")
    ls.add_argument("--spin-time", type=non_negative, default=0.5, metavar="SEC",
                    help="without NODE: list once the graph has not changed for SEC seconds (default 0.5)")
    _common(ls)
    ls.set_defaults(run=run_list)

    get = verbs.add_parser("get", help="value of a parameter")
    get.add_argument("node")
    get.add_argument("name")
    get.add_argument("--hide-type", action="store_true", help="print the value only")
    _common(get)
    get.set_defaults(run=run_get)

    put = verbs.add_parser("set", help="set a parameter (the node may refuse, with its reason)",
                           description="Set a parameter; the value is read as YAML (5 is an integer, "
                                       "5.0 a double, [1.0, 2.0] a double array, anything else a string).")
    put.add_argument("node")
    put.add_argument("name")
    put.add_argument("value", help="the value, read as YAML (-.inf, -1e-3 and -5 are values, not options)")
    # argparse takes only plain negative numbers for values; YAML's -.inf, -1e3 are values here too
    put._negative_number_matcher = _NEGATIVE_VALUE
    _common(put)
    put.set_defaults(run=run_set)

    desc = verbs.add_parser("describe", help="type, description and constraints of parameters")
    desc.add_argument("node")
    desc.add_argument("names", nargs="+")
    _common(desc)
    desc.set_defaults(run=run_describe)

    dump = verbs.add_parser("dump", help="print every parameter as a parameter file")
    dump.add_argument("node")
    dump.add_argument("-o", "--output", help="write to this file instead of printing")
    _common(dump)
    dump.set_defaults(run=run_dump)

    load = verbs.add_parser("load", help="set parameters from a parameter file",
                            description="Set the parameters a parameter file gives for this node "
                                        "(its /node and /** entries), one by one.")
    load.add_argument("node")
    load.add_argument("file")
    load.add_argument("--no-use-wildcard", action="store_true", help="ignore the /** entry")
    _common(load)
    load.set_defaults(run=run_load)


def _common(p) -> None:
    p.add_argument("--timeout", type=positive, default=DISCOVERY_TIMEOUT, metavar="SEC",
                   help=f"wait up to SEC seconds for the node and its answers (default {DISCOVERY_TIMEOUT:g})")
    add_no_daemon(p)


class _Remote:
    """Parameter services of one remote node, called synchronously."""

    def __init__(self, node, name: str, timeout: float):
        self.name = find_node(node, name, timeout)
        self.node, self.timeout = node, timeout
        self.client = parameter_client(node, self.name)
        if not spin_until(node, self.client.services_are_ready, timeout):
            raise TimeoutError(f"node {self.name} offers no parameter services (started without them?)")

    def call(self, future, service: str):
        return spin_future(self.node, future, self.timeout, f"{self.name}/{service}")

    def list(self) -> list[str]:
        return sorted(self.call(self.client.list_parameters(), "list_parameters").result.names)

    def get(self, names: list[str]) -> list[ParameterValue]:
        return list(self.call(self.client.get_parameters(names), "get_parameters").values)

    def set(self, params: list[ParameterMsg]):
        return list(self.call(self.client.set_parameters(params), "set_parameters").results)

    def describe(self, names: list[str]):
        return list(self.call(self.client.describe_parameters(names), "describe_parameters").descriptors)


def run_list(args) -> int:
    with graph_node("param") as node:
        if args.node:
            names = [find_node(node, args.node, args.timeout)]
        else:
            settle(node, args.spin_time)
            names = node_names(node)
        for name in names:
            remote = _Remote(node, name, args.timeout)
            print(f"{remote.name}:")
            for param in remote.list():
                print(f"  {param}")
    return 0


def run_get(args) -> int:
    with graph_node("param") as node:
        remote = _Remote(node, args.node, args.timeout)
        value = _declared(remote, [args.name], remote.get([args.name]))[0]
        if value.type == ParameterType.PARAMETER_NOT_SET:
            print("Parameter not set.")
            return 1
        python = parameter_value_to_python(value)
        if value.type == ParameterType.PARAMETER_BYTE_ARRAY:
            python = [b[0] if isinstance(b, bytes) else b for b in python]
        print(python if args.hide_type else f"{_GET_LABELS[value.type]}: {python}")
    return 0


def run_set(args) -> int:
    value = parameter_value(args.value)
    with graph_node("param") as node:
        remote = _Remote(node, args.node, args.timeout)
        result = remote.set([ParameterMsg(name=args.name, value=value)])[0]
    if result.successful:
        print("Set parameter successful" + (f": {result.reason}" if result.reason else ""))
        return 0
    print("Setting parameter failed" + (f": {result.reason}" if result.reason else ""), file=sys.stderr)
    return 1


def parameter_value(text: str) -> ParameterValue:
    """A command-line value read as YAML, as ``ros2 param set`` does; ValueError saying why not."""
    try:
        python = yaml.safe_load(text)
    except (yaml.YAMLError, RecursionError):   # not YAML ('{a: 1', '!!tag x'): the text itself, a string
        return ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=text)
    ints = python if isinstance(python, list) else [python]
    for v in ints:
        if isinstance(v, int) and not isinstance(v, bool) and not _INT64[0] <= v <= _INT64[1]:
            raise ValueError(f"{v} is beyond the 64-bit integers ROS 2 parameters hold; write it as {float(v):g} "
                             "for a double")
    return get_parameter_value(text)


def _declared(remote: _Remote, names: list[str], answers: list) -> list:
    """The answers for ``names``, or a ValueError naming the parameters the node does not have."""
    if len(answers) == len(names):
        return answers
    known = set(remote.list())
    missing = [n for n in names if n not in known]
    raise ValueError(f"node {remote.name} has no parameter {', '.join(missing) or ', '.join(names)}; "
                     f"`cdpr param list {remote.name}` shows its {len(known)} parameters")


def run_describe(args) -> int:
    with graph_node("param") as node:
        remote = _Remote(node, args.node, args.timeout)
        for d in _declared(remote, args.names, remote.describe(args.names)):
            print(format_descriptor(d))
    return 0


def format_descriptor(d) -> str:
    """The text ``ros2 param describe`` prints for one parameter."""
    lines = [f"Parameter name: {d.name}", f"  Type: {_TYPE_NAMES.get(d.type, d.type)}"]
    if d.description:
        lines.append(f"  Description: {d.description}")
    constraints = []
    if d.read_only:
        constraints.append("Read only: true")
    if d.dynamic_typing:
        constraints.append("Dynamic typing: true")
    for r in list(d.floating_point_range) + list(d.integer_range):
        constraints += [f"Min value: {r.from_value}", f"Max value: {r.to_value}"]
        if r.step:
            constraints.append(f"Step: {r.step}")
    if d.additional_constraints:
        constraints.append(f"Additional constraints: {d.additional_constraints}")
    if constraints:
        lines.append("  Constraints:")
        lines += [f"    {c}" for c in constraints]
    return "\n".join(lines)


def run_dump(args) -> int:
    with graph_node("param") as node:
        remote = _Remote(node, args.node, args.timeout)
        names = remote.list()
        values = remote.get(names) if names else []
    params: dict = {}
    for name, value in zip(names, values):
        python = parameter_value_to_python(value)
        if value.type == ParameterType.PARAMETER_BYTE_ARRAY:
            python = [b[0] if isinstance(b, bytes) else b for b in python]
        _nest(params, name.split("."), python)
    text = yaml.safe_dump({remote.name: {"ros__parameters": params}}, sort_keys=False, default_flow_style=False)
    if args.output:
        Path(args.output).write_text(text)
        print(f"wrote {args.output}")
    else:
        print(text, end="")
    return 0


def _nest(tree: dict, path: list[str], value) -> None:
    for part in path[:-1]:
        tree = tree.setdefault(part, {})
    tree[path[-1]] = value


def run_load(args) -> int:
    entries = read_parameter_file(args.file)       # a broken file is named before the graph is asked
    with graph_node("param") as node:
        remote = _Remote(node, args.node, args.timeout)
        params = node_parameters(entries, args.file, remote.name, not args.no_use_wildcard)
        # read-only parameters holding the file's value already are left alone (a dump loads back)
        names = list(params)
        current = dict(zip(names, remote.get(names)))
        read_only = {d.name for d in remote.describe(names) if d.read_only}
        params = {n: v for n, v in params.items() if not (n in read_only and _same(v, current[n]))}
        results = remote.set([ParameterMsg(name=n, value=v) for n, v in params.items()]) if params else []
    failed = 0
    for name, result in zip(params, results):
        if result.successful:
            print(f"Set parameter {name} successful")
        else:
            failed += 1
            print(f"Set parameter {name} failed" + (f": {result.reason}" if result.reason else ""), file=sys.stderr)
    return 1 if failed else 0


def _same(a: ParameterValue, b: ParameterValue) -> bool:
    return a.type == b.type and parameter_value_to_python(a) == parameter_value_to_python(b)


def parameters_for_node(path: str, node_name: str, use_wildcard: bool = True) -> dict[str, ParameterValue]:
    """Parameters a standard parameter file gives ``node_name`` (``/**`` first, then its own entry)."""
    return node_parameters(read_parameter_file(path), path, node_name, use_wildcard)


def read_parameter_file(path: str) -> dict[str, dict[str, ParameterValue]]:
    """Each entry of a standard parameter file (node name or ``/**``) with its parameters, flattened
    to dotted names; ValueError naming the file for YAML, encoding and nesting errors, for anything
    but a mapping of ``{ros__parameters: {...}}`` entries and for values no parameter can hold."""
    data = load_yaml(path, "parameter file")
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a parameter file maps node names to {{ros__parameters: ...}}, "
                         f"got a {type(data).__name__} at the top level")
    entries = {}
    for key, entry in data.items():
        if not isinstance(entry, dict) or "ros__parameters" not in entry:
            raise ValueError(f"{path}: entry {key!r} has no ros__parameters")
        tree = entry["ros__parameters"] or {}
        if not isinstance(tree, dict):
            raise ValueError(f"{path}: {key}.ros__parameters maps names to values, got a {type(tree).__name__}")
        entries[str(key)] = params = {}
        try:
            _flatten(tree, "", params)
        except ValueError as exc:
            raise ValueError(f"{path}: {key}: {exc}") from None
    return entries


def node_parameters(entries: dict, path: str, node_name: str, use_wildcard: bool = True) -> dict[str, ParameterValue]:
    """The parameters the entries of parameter file ``path`` give ``node_name`` (``/**`` first, then its own)."""
    keys = (["/**"] if use_wildcard else []) + [node_name, node_name.lstrip("/")]
    found = [entries[key] for key in keys if key in entries]
    if not found:
        raise ValueError(f"{path} has no parameters for {node_name}; entries: {', '.join(entries) or '(none)'}")
    return {name: value for params in found for name, value in params.items()}


def _flatten(tree: dict, prefix: str, out: dict) -> None:
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            _flatten(value, f"{name}.", out)
        else:
            if any(isinstance(v, int) and not -2**63 <= v < 2**63 for v in (value if isinstance(value, list) else [value])):
                raise ValueError(f"parameter {name}: {value!r} is beyond the 64-bit integers of ROS 2 parameters")
            try:
                out[name] = Parameter(name, value=value).get_parameter_value()
            except TypeError:
                raise ValueError(f"parameter {name}: unsupported value {value!r}") from None
