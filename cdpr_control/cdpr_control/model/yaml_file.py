"""Reading the project's YAML files (robots, parameter files, launch files) strictly, with errors in words.

``yaml.safe_load`` keeps the last of two equal keys (``mass: 1.0`` then ``mass: 25.0`` is silently
25 kg), recurses once per nesting level (a file nested a few thousand levels deep ends in
"maximum recursion depth exceeded") and reports a file that is not UTF-8 as a bare codec message.
:func:`load_yaml` refuses each with a :class:`YamlFileError` naming the file and what is wrong:

- ``robot.yaml: duplicate key 'mass' at line 9 (first at line 7)``;
- ``robot.yaml: nested deeper than 64 levels (line 1, column 65)``;
- ``robot.yaml: not UTF-8 text (byte 0xff at line 1, column 1; a UTF-16, Latin-1 or binary file?)``;
- ``robot.yaml:3:7: not valid YAML: mapping values are not allowed here``;
- ``robots/: is a directory, not a robot file``, ``pipe: is not a regular file, not a robot file`` and
  ``cannot read robot file: Permission denied``.
"""
from __future__ import annotations

from pathlib import Path

import yaml

MAX_DEPTH = 64   # levels of nested mappings and lists; the project's files use fewer than 10


class YamlFileError(ValueError):
    """A YAML file that cannot be read or parsed; the message names the file."""


class _Refused(Exception):
    """A problem found while composing or constructing, before the file's name is known to the loader."""

    def __init__(self, message: str, mark=None):
        super().__init__(message)
        self.message = message
        self.mark = mark


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys and nesting deeper than MAX_DEPTH, both before Python
    recursion does (the composer recurses per level; the check runs on entering each)."""

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels", self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node, deep=False):
        first_line: dict = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue                      # `<<: *base` may override keys: that is what it is for
            key = self.construct_object(key_node, deep=True)
            try:
                earlier = first_line.get(key)
            except TypeError:                 # an unhashable key: SafeLoader's own error names it
                continue
            line = key_node.start_mark.line + 1
            if earlier is not None:
                raise _Refused(f"duplicate key {key!r} at line {line} (first at line {earlier})")
            first_line[key] = line
        return super().construct_mapping(node, deep)


def read_text(path: str | Path, what: str = "file") -> str:
    """The file's text, decoded as UTF-8; YamlFileError naming the file for a directory, a file
    that cannot be read or bytes that are not UTF-8 (with the line and column of the first)."""
    path = Path(path)
    if path.is_dir():
        raise YamlFileError(f"{path}: is a directory, not a {what}")
    if path.exists() and not path.is_file():     # a fifo or a device would block or never end
        raise YamlFileError(f"{path}: is not a regular file, not a {what}")
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise YamlFileError(f"{path}: no such {what}") from None
    except OSError as exc:
        raise YamlFileError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        before = data[:exc.start]
        line = before.count(b"\n") + 1
        column = exc.start - (before.rfind(b"\n") + 1) + 1
        raise YamlFileError(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} at line {line}, column {column}; "
                            "a UTF-16, Latin-1 or binary file?)") from None


def parse_yaml(text: str, source: str | Path):
    """The YAML document in ``text``; YamlFileError naming ``source`` (a file name) and the problem."""
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - _StrictLoader is a SafeLoader
    except _Refused as exc:
        where = "" if exc.mark is None else f" (line {exc.mark.line + 1}, column {exc.mark.column + 1})"
        raise YamlFileError(f"{source}: {exc.message}{where}") from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = "" if mark is None else f":{mark.line + 1}:{mark.column + 1}"
        problem = exc.problem or exc.context or "parse error"
        raise YamlFileError(f"{source}{where}: not valid YAML: {problem}") from None
    except yaml.reader.ReaderError as exc:
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        raise YamlFileError(f"{source}: not YAML text: control character U+{code:04X} at character {exc.position + 1} "
                            "(a binary file?)") from None
    except yaml.YAMLError as exc:
        raise YamlFileError(f"{source}: not valid YAML: {exc}") from None


def load_yaml(path: str | Path, what: str = "YAML file"):
    """The parsed contents of a YAML file (read_text, then parse_yaml): every error names the file."""
    return parse_yaml(read_text(path, what), path)
