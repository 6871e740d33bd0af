"""Every `cdpr ...` command shown in README.md and docs/*.md is one the tool takes today.

The commands are read from the documents (inline code and the lines of code blocks). A synopsis
(placeholders such as FILE, [options], ...) must name a command that exists; a concrete command line
must parse with the real parser (an option or verb renamed since is a failure). Those that need no
robot and finish at once run: `cdpr launch ... --show` resolves the launch file, its arguments and
`--only`/`--exclude` (and starts nothing), `cdpr robot` and `cdpr program check` do their work.
The rest (a graph to talk to, minutes of simulation) is parsed here; tests/tools/test_docs_graph_commands.py
runs the concrete graph commands against the launched graph, tests/tools/test_cli_*.py and the graph
tests run the other verbs.
"""
from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from cdpr_tools import cli

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PLACEHOLDER = re.compile(r"[\[\]{}<>|]|\.\.\.|\b[A-Z][A-Z_]{2,}\b")
RUN = {"robot", "program check", "launch"}
REFERENCE = re.compile(r"--?[a-z][a-z-]*|[a-z][a-z-]*(/[a-z][a-z-]*)*")


def documented_commands() -> list[tuple[str, int, str]]:
    """(document, line, command) of every `cdpr ...` in the documents."""
    found = []
    for doc in DOCS:
        fenced = False
        lines = doc.read_text(encoding="utf-8").splitlines()
        for number, line in enumerate(lines, 1):
            if line.lstrip().startswith("```"):
                fenced = not fenced
                continue
            if fenced:
                text = line.strip().removeprefix("$ ")
                if text.startswith("cdpr "):
                    found.append((doc.name, number, text.split(" #")[0].strip()))
            else:
                found += [(doc.name, number, m) for m in re.findall(r"`(cdpr [^`]+)`", line)]
    return found


COMMANDS = documented_commands()


def test_the_documents_show_commands():
    assert len(COMMANDS) > 50
    assert {"README.md", "tools.md"} <= {doc for doc, _, _ in COMMANDS}


def _subparser(path: list[str]):
    """The parser of command ``path`` (e.g. ["bag", "play"]); an AssertionError names what is missing."""
    parser = cli.build_parser(path[:1])
    for word in path:
        sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        assert sub is not None and word in sub.choices, f"no command {' '.join(path)} (no {word!r})"
        parser = sub.choices[word]
    return parser


def _is_reference(argv: list[str]) -> bool:
    """Only the command, verbs of it (``list/echo/hz``) and bare options: prose, not a command line."""
    if not all(REFERENCE.fullmatch(a) for a in argv):
        return False
    words = [a for a in argv if not a.startswith("-")]
    if len(words) == 1:
        return True
    sub = next((a for a in _subparser(words[:1])._actions if isinstance(a, argparse._SubParsersAction)), None)
    return len(words) == 2 and sub is not None and all(w in sub.choices for w in words[1].split("/"))


def _check_reference(argv: list[str]) -> None:
    """Prose naming a command, its verbs (``list/echo/hz``) or options (``--payload``): each exists."""
    words = [a for a in argv if not a.startswith("-")]
    options = [a for a in argv if a.startswith("-")]
    for alternative in words[1].split("/") if len(words) > 1 else [None]:
        parser = _subparser(words[:1] + ([alternative] if alternative else []))
        for option in options:
            assert option in parser._option_string_actions, f"{' '.join(words)} has no option {option}"


def _parse(argv: list[str]):
    try:
        return cli.build_parser(argv).parse_args(argv)
    except SystemExit as exc:
        if exc.code != 0:
            raise AssertionError(f"does not parse (exit {exc.code})") from None
        return None


@pytest.mark.parametrize("doc, line, command", COMMANDS, ids=[f"{d}:{n}" for d, n, _ in COMMANDS])
def test_documented_command_is_one_the_tool_takes(doc, line, command, capsys):
    argv = shlex.split(command)[1:]
    if not argv or argv[0].startswith("-"):
        _parse(argv or ["--help"])
        return
    if argv[0].endswith(":"):                          # an example of the tool's output, not a command
        return
    assert argv[0] in cli.COMMANDS, f"{doc}:{line}: no command {argv[0]!r} ({command})"
    if _is_reference(argv):                            # prose naming a command, verb or option
        _check_reference(argv)
        return
    if PLACEHOLDER.search(command):                   # a synopsis: the command and verb exist
        verb = [argv[0]] + [a for a in argv[1:2] if re.fullmatch(r"[a-z][a-z-]*", a)]
        _parse(verb + ["--help"])
        return
    args = _parse(argv)
    key = " ".join(argv[:2]) if argv[0] == "program" else argv[0]
    if args is None or key not in RUN or any(a.startswith("my_") for a in argv):   # (my_*: the reader's own file)
        return
    if argv[0] == "launch":
        argv = argv + ["--show"]
    rc = cli.main(argv)
    assert rc == 0, f"{doc}:{line}: `{command}` exited {rc}: {capsys.readouterr().err[-500:]}"
