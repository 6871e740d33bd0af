"""ROS 2 YAML launch files, read into the :class:`~cdpr_tools.launch.LaunchDescription` the launcher runs.

The same file works with ``ros2 launch`` on a full ROS 2 install and with ``cdpr launch`` on the
pip wheels (``launch``/``launch_ros`` are not on PyPI). ``cdpr launch`` reads the subset a node
graph needs and names the file and the entry of anything else, rather than ignoring it:

- actions (entries of the top-level ``launch:`` list): ``arg`` (``name``, ``default``,
  ``description``), ``let`` (``name``, ``value``), ``set_parameter`` (``name``, ``value``; before
  the first node: cdpr launch gives it to every node, as ros2 launch does to the nodes after it),
  ``node``;
- ``node`` attributes: ``pkg``, ``exec``, ``name``, ``namespace``, ``param`` (``from: FILE``,
  ``name``/``value``, or ``name`` with a nested ``param`` list), ``remap`` (``from``/``to``),
  ``ros_args`` (a string), ``on_exit: shutdown`` (its end ends the launch), ``output`` (accepted;
  cdpr launch prints every node's output, prefixed with its name);
- ``if``/``unless`` on ``let``, ``set_parameter`` and ``node`` (true, false, 1 or 0 after
  substitution), so optional stages can be switched by an argument;
- substitutions in any string: ``$(var NAME)``, ``$(find-pkg-share PKG)``, ``$(env NAME [DEFAULT])``.
  A parameter value that is a substitution is typed as YAML, as ``launch_ros`` does
  (``value: $(var seed)`` with seed 0 is the integer 0).

``pkg``/``exec`` become a Python module: the package's console-script entry point of that name
when the installed metadata has one, else the module ``<pkg>.nodes.<exec>`` or ``<pkg>.<exec>``
(the convention every node of this project follows, so a source checkout runs before its metadata
is reinstalled).
A relative parameter file is taken relative to the launch file.
"""
from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import re
import shlex
from pathlib import Path

import yaml

from cdpr_control.model.yaml_file import YamlFileError, load_yaml
from cdpr_tools.launch import LaunchDescription, NodeSpec
from cdpr_tools.share import package_share

ACTIONS = ("arg", "let", "set_parameter", "node")
NODE_KEYS = ("pkg", "exec", "name", "namespace", "param", "remap", "ros_args", "on_exit", "output", "if", "unless")
CONDITION_KEYS = ("if", "unless")
_TRUE, _FALSE = ("true", "1"), ("false", "0")  # what launch's IfCondition accepts, case-insensitive
_SUBSTITUTION = re.compile(r"\$\(([a-z][\w-]*)((?:\s+[^\s)]+)*)\s*\)")


class LaunchFileError(ValueError):
    """A launch file cdpr launch cannot run; the message names the file and the entry."""


def load_launch_file(path: str | os.PathLike, arguments: dict | None = None) -> LaunchDescription:
    """Read a ROS 2 YAML launch file; ``arguments`` (NAME -> value) set its ``arg`` declarations."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"launch file {path} not found")
    try:
        data = load_yaml(path, "launch file")   # YAML, encoding and nesting errors name the file
    except YamlFileError as exc:
        raise LaunchFileError(str(exc)) from None
    if not isinstance(data, dict) or set(data) != {"launch"} or not isinstance(data["launch"], list):
        raise LaunchFileError(f"{path}: a ROS 2 YAML launch file is a mapping with one key, 'launch:', "
                              "holding a list of actions")
    reader = _Reader(path, {str(k): str(v) for k, v in (arguments or {}).items()})
    for i, entry in enumerate(data["launch"]):
        reader.action(entry, f"{path}: launch[{i}]")
    unknown = sorted(set(reader.given) - set(reader.declared))
    if unknown:
        raise LaunchFileError(f"{path}: unknown argument {', '.join(unknown)}; "
                              f"arguments: {', '.join(reader.declared) or '(none)'}")
    if not reader.nodes:
        raise LaunchFileError(f"{path}: no node")
    return LaunchDescription(nodes=reader.nodes, parameters=reader.common, source=path)


def find_launch_file(package: str, name: str) -> Path:
    """``ros2 launch PACKAGE NAME``: the file called ``name`` anywhere in the package's share."""
    share = package_share(package)
    found = sorted(share.rglob(name))
    if not found:
        raise FileNotFoundError(f"no launch file {name!r} in {share} (package {package})")
    if len(found) > 1:
        raise LookupError(f"several files {name!r} in {share}: {', '.join(str(p) for p in found)}")
    return found[0]


def resolve_executable(package: str, executable: str, where: str) -> NodeSpec:
    """The node spec (module or entry point) that runs ``ros2 run PACKAGE EXECUTABLE``."""
    try:
        points = importlib.metadata.distribution(package).entry_points
    except importlib.metadata.PackageNotFoundError:
        points = ()
    for point in points:
        if point.group == "console_scripts" and point.name == executable:
            module, _, func = point.value.partition(":")
            if func.strip() in ("", "main"):
                return NodeSpec(module=module.strip())
            return NodeSpec(entry_point=executable)
    candidates = (f"{package}.nodes.{executable}", f"{package}.{executable}")
    for module in candidates:
        try:
            if importlib.util.find_spec(module) is not None:
                return NodeSpec(module=module)
        except ModuleNotFoundError:  # the package (or its nodes sub-package) is missing
            continue
    raise LookupError(f"{where}: package {package!r} has no executable {executable!r} "
                      f"(no console script of that name, no module {' or '.join(candidates)})")


class _Reader:
    def __init__(self, path: Path, given: dict):
        self.path, self.given = path, given
        self.variables: dict[str, str] = {}
        self.declared: list[str] = []
        self.common: dict = {}
        self.nodes: list[NodeSpec] = []

    # -- actions ----------------------------------------------------------------------------------
    def action(self, entry, where: str) -> None:
        if not isinstance(entry, dict) or len(entry) != 1:
            raise LaunchFileError(f"{where}: an action is a mapping with one key ({', '.join(ACTIONS)})")
        (kind, body), = entry.items()
        if kind not in ACTIONS:
            raise LaunchFileError(f"{where}: '{kind}' is not supported by cdpr launch "
                                  f"(supported actions: {', '.join(ACTIONS)})")
        if not isinstance(body, dict):
            raise LaunchFileError(f"{where}: {kind} takes a mapping of attributes")
        where = f"{where} ({kind})"
        if kind != "arg" and not self._condition(body, where):
            return
        getattr(self, f"_{kind}")({k: v for k, v in body.items() if k not in CONDITION_KEYS}, where)

    def _condition(self, body: dict, where: str) -> bool:
        """``if:``/``unless:`` of an action, as launch's IfCondition/UnlessCondition read them."""
        result = True
        for key in CONDITION_KEYS:
            if key in body:
                text = self.text(body[key], where).strip().lower()
                if text not in _TRUE + _FALSE:
                    raise LaunchFileError(f"{where}: {key}: {text!r} is not true, false, 1 or 0")
                result = result and ((text in _TRUE) == (key == "if"))
        return result

    def _arg(self, body: dict, where: str) -> None:
        self._keys(body, ("name", "default", "description"), where)
        name = self._name(body, where)
        self.declared.append(name)
        if name in self.given:
            self.variables[name] = self.given[name]
        elif "default" in body:
            self.variables[name] = self.text(body["default"], where)
        else:
            raise LaunchFileError(f"{where}: argument {name} has no default; give it as {name}:=VALUE")

    def _let(self, body: dict, where: str) -> None:
        self._keys(body, ("name", "value"), where)
        self.variables[self._name(body, where)] = self.text(body.get("value", ""), where)

    def _set_parameter(self, body: dict, where: str) -> None:
        self._keys(body, ("name", "value"), where)
        if self.nodes:
            raise LaunchFileError(f"{where}: put set_parameter before the first node "
                                  "(cdpr launch gives it to every node of the file)")
        self.common[self._name(body, where)] = self.value(body.get("value"), where)

    def _node(self, body: dict, where: str) -> None:
        self._keys(body, NODE_KEYS, where)
        for key in ("pkg", "exec"):
            if key not in body:
                raise LaunchFileError(f"{where}: a node needs '{key}'")
        spec = resolve_executable(self.text(body["pkg"], where), self.text(body["exec"], where), where)
        if "name" in body:
            spec.name = self.text(body["name"], where)
        if "namespace" in body:
            spec.namespace = self.text(body["namespace"], where)
        spec.parameters = self.parameters(body.get("param") or [], f"{where} param")
        for j, remap in enumerate(body.get("remap") or []):
            self._keys(remap, ("from", "to"), f"{where} remap[{j}]", required=("from", "to"))
            spec.remappings[self.text(remap["from"], where)] = self.text(remap["to"], where)
        if "ros_args" in body:
            spec.ros_args = shlex.split(self.text(body["ros_args"], where))
        on_exit = body.get("on_exit")
        if on_exit not in (None, "shutdown"):
            raise LaunchFileError(f"{where}: on_exit: {on_exit} is not supported by cdpr launch (only 'shutdown')")
        spec.required = on_exit == "shutdown"
        spec.target()  # fail now on a missing entry point
        self.nodes.append(spec)

    def parameters(self, entries, where: str) -> list:
        """Node parameters in order: file paths and inline mappings (nested for ``name`` + ``param``)."""
        if not isinstance(entries, list):
            raise LaunchFileError(f"{where}: param is a list")
        result: list = []
        inline: dict = {}
        for j, entry in enumerate(entries):
            at = f"{where}[{j}]"
            if not isinstance(entry, dict):
                raise LaunchFileError(f"{at}: a param entry is a mapping (from, or name and value)")
            if "from" in entry:
                self._keys(entry, ("from",), at)
                if inline:
                    result.append(inline)
                    inline = {}
                result.append(self.parameter_file(self.text(entry["from"], at), at))
            else:
                self._keys(entry, ("name", "value", "param"), at, required=("name",))
                name = self._name(entry, at)
                if "param" in entry:
                    nested = self.parameters(entry["param"], f"{at} param")
                    if any(not isinstance(p, dict) for p in nested):
                        raise LaunchFileError(f"{at}: a nested param list holds name/value entries only")
                    inline[name] = {k: v for p in nested for k, v in p.items()}
                else:
                    inline[name] = self.value(entry.get("value"), at)
        if inline:
            result.append(inline)
        return result

    def parameter_file(self, text: str, where: str) -> str:
        path = Path(text)
        path = path if path.is_absolute() else self.path.parent / path
        if not path.is_file():
            raise FileNotFoundError(f"{where}: parameter file {path} not found")
        return str(path)

    # -- substitutions ----------------------------------------------------------------------------
    def text(self, value, where: str) -> str:
        """A string with every substitution replaced."""
        if isinstance(value, (dict, list)):
            raise LaunchFileError(f"{where}: expected a string, got {type(value).__name__}")
        return _SUBSTITUTION.sub(lambda m: self._substitute(m, where), str(value))

    def value(self, value, where: str):
        """A parameter value: YAML-typed when it holds substitutions, as launch_ros does."""
        if isinstance(value, list):
            return [self.value(v, where) for v in value]
        if isinstance(value, str) and "$(" in value:
            text = self.text(value, where)
            return yaml.safe_load(text) if text.strip() else text
        return value

    def _substitute(self, match: re.Match, where: str) -> str:
        kind, args = match.group(1), match.group(2).split()
        if kind == "var" and len(args) == 1:
            if args[0] not in self.variables:
                raise LaunchFileError(f"{where}: $(var {args[0]}) is not declared (by arg or let) before it is used")
            return self.variables[args[0]]
        if kind == "find-pkg-share" and len(args) == 1:
            return str(package_share(args[0]))
        if kind == "env" and len(args) in (1, 2):
            if args[0] in os.environ:
                return os.environ[args[0]]
            if len(args) == 2:
                return args[1]
            raise LaunchFileError(f"{where}: environment variable {args[0]} is not set and {match.group(0)} has no default")
        raise LaunchFileError(f"{where}: substitution {match.group(0)} is not supported by cdpr launch "
                              "(supported: $(var NAME), $(find-pkg-share PKG), $(env NAME [DEFAULT]))")

    # -- checks -----------------------------------------------------------------------------------
    def _name(self, body: dict, where: str) -> str:
        if "name" not in body:
            raise LaunchFileError(f"{where}: 'name' is missing")
        return self.text(body["name"], where)

    @staticmethod
    def _keys(body, allowed, where: str, required=()) -> None:
        if not isinstance(body, dict):
            raise LaunchFileError(f"{where}: expected a mapping")
        unknown = sorted(set(map(str, body)) - set(allowed))
        if unknown:
            raise LaunchFileError(f"{where}: '{', '.join(unknown)}' is not supported by cdpr launch "
                                  f"(supported: {', '.join(allowed)})")
        missing = [k for k in required if k not in body]
        if missing:
            raise LaunchFileError(f"{where}: '{', '.join(missing)}' is missing")
