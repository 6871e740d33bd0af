"""Message definitions as rosbag2 stores them in MCAP schemas (encoding ``ros2msg``).

rosbag2 (rosbag2_cpp ``LocalMessageDefinitionSource``) reads ``share/<pkg>/msg/<Type>.msg`` of the
installed package and appends every nested type, depth first, each dependency once, in sorted
order per file, behind a separator line and ``MSG: pkg/Type``. Readers (``ros2 bag``, Foxglove,
``mcap_ros2``, ``rosbags``) rebuild the types from that text, so it must be the same text.
"""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path

from cdpr_tools.message_convert import split_type_name

SEPARATOR = "=" * 80 + "\n"
ENCODING = "ros2msg"
# the field-type pattern and primitive names of rosbag2's LocalMessageDefinitionSource
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}


def share_dir(package: str) -> Path:
    """``share/<package>`` of an installed package: AMENT_PREFIX_PATH first, then this environment."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    for prefix in prefixes:
        candidate = Path(prefix) / "share" / package
        if candidate.is_dir():
            return candidate
    raise LookupError(f"package {package!r} not found in {', '.join(prefixes)}")


def _interface_file(type_name: str, suffix: str) -> Path:
    pkg, kind, name = split_type_name(type_name)
    path = share_dir(pkg) / kind / f"{name}{suffix}"
    if not path.is_file():
        raise LookupError(f"no definition of {type_name}: {path} does not exist")
    return path


@functools.lru_cache(maxsize=None)
def _msg_text(type_name: str) -> str:
    return _interface_file(type_name, ".msg").read_text()


def _dependencies(type_name: str, text: str | None = None) -> list[str]:
    """Nested message types named in a .msg file (or in ``text`` of that package), as sorted
    ``pkg/Type`` names."""
    package = split_type_name(type_name)[0]
    deps = set()
    for field_type in _FIELD_TYPE.findall(_msg_text(type_name) if text is None else text):
        if field_type in _PRIMITIVES:
            continue
        deps.add(field_type if "/" in field_type else f"{package}/{field_type}")
    return sorted(deps)


@functools.lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """Full ``ros2msg`` schema text of ``pkg/msg/Type`` with all nested definitions appended."""
    return _with_dependencies(type_name, _msg_text(type_name))


def _with_dependencies(type_name: str, text: str) -> str:
    """``text`` (a definition in ``type_name``'s package) with every nested definition appended."""
    seen: set[str] = set()

    def append(name: str, own: str | None = None) -> str:
        out = _msg_text(name) if own is None else own
        for dep in _dependencies(name, own):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + SEPARATOR + f"MSG: {dep}\n" + append(dep)
        return out

    return append(type_name, text)


@functools.lru_cache(maxsize=None)
def service_definitions(type_name: str) -> tuple[str, str]:
    """``ros2msg`` schema texts of the request and the response of ``pkg/srv/Type`` (the two
    halves of its .srv file, each with its nested definitions), as Foxglove's service schemas."""
    request, sep, response = _interface_file(type_name, ".srv").read_text().partition("\n---")
    if not sep:
        raise LookupError(f"{type_name}: no '---' between request and response")
    return _with_dependencies(type_name, request.rstrip("\n") + "\n"), \
        _with_dependencies(type_name, response.lstrip("\n"))


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """``RIHS01_...`` type description hash from the package's generated ``<Type>.json``, or ""."""
    try:
        data = json.loads(_interface_file(type_name, ".json").read_text())
    except (LookupError, ValueError):
        return ""
    wanted = "/".join(split_type_name(type_name))
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == wanted:
            return entry.get("hash_string", "")
    return ""
