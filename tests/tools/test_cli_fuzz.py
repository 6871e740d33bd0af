"""Bad input to every `cdpr` verb that needs no running graph (issues 27, 28): missing paths,
directories, paths nobody can read (a fifo: root reads any file, but a fifo without a writer would
block a reader forever), files that are not UTF-8 (UTF-16, Latin-1, binary), invalid or wrongly
shaped YAML, negative and non-finite numbers. Each must end with exit status 1 or 2 and one error
line naming the file or argument, never a traceback, a hang or a signal.

Most cases run in-process (cdpr_tools.cli.main with argv, fast); a few run the `cdpr` command as
a subprocess, where an abort or a signal would show as the exit status.
"""
import os
import re
import subprocess
import sys

import pytest

from cdpr_control.model.robot import robot_path
from cdpr_test_nodes.graph import subprocess_env
from cdpr_tools import cli

SUBPROCESS_TIMEOUT = 120.0   # s; a case that has not ended by then is a hang


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Bad inputs, one of each kind, by name; `{NAME}` in a case's argv is replaced by the path."""
    d = tmp_path_factory.mktemp("bad_inputs")
    mini = robot_path("ipanema3_mini").read_text()
    made = {
        "missing": d / "missing.yaml",
        "directory": d / "directory.yaml",
        "fifo": d / "fifo.yaml",
        "utf16": d / "utf16.yaml",
        "latin1": d / "latin1.yaml",
        "binary": d / "binary.yaml",
        "empty": d / "empty.yaml",
        "invalid_yaml": d / "invalid.yaml",
        "yaml_list": d / "list.yaml",
        "deep_yaml": d / "deep.yaml",
        "duplicate_key": d / "duplicate.yaml",
        "params_list": d / "params_list.yaml",
        "params_huge_int": d / "params_huge_int.yaml",
        "launch_no_list": d / "launch_no_list.yaml",
        "robot_home_outside": d / "robot_home_outside.yaml",
        "gcode_latin1": d / "latin1.gcode",
        "gcode_utf16": d / "utf16.gcode",
        "gcode_directory": d / "directory.gcode",
        "gcode_fifo": d / "fifo.gcode",
        "gcode_tension": d / "tension.gcode",
        "gcode_ruckig": d / "ruckig.gcode",
        "not_a_bag": d / "not_a_bag.mcap",
        "empty_mcap": d / "empty.mcap",
    }
    made["directory"].mkdir()
    made["gcode_directory"].mkdir()
    os.mkfifo(made["fifo"])
    os.mkfifo(made["gcode_fifo"])
    made["utf16"].write_bytes(mini.encode("utf-16"))
    made["latin1"].write_bytes(mini.replace("IPAnema 3 Mini", "IPAnema 3 Mini à").encode("latin-1"))
    made["binary"].write_bytes(bytes(range(256)) * 8)
    made["empty"].write_text("")
    made["invalid_yaml"].write_text("launch:\n  - node: {pkg: cdpr_sim, exec: winch_platform_sim\n")
    made["yaml_list"].write_text("- 1\n- 2\n")
    made["deep_yaml"].write_text("[" * 3000 + "]" * 3000)
    made["duplicate_key"].write_text(mini.replace("  mass:", "  mass: 25.0\n  mass:", 1))
    made["params_list"].write_text("/**:\n  ros__parameters: [1, 2]\n")
    made["params_huge_int"].write_text("/**:\n  ros__parameters:\n    gain: 100000000000000000000000\n")
    made["launch_no_list"].write_text("launch: {node: x}\n")
    made["robot_home_outside"].write_text(mini.replace("home: [0.0, 0.0, 0.0,", "home: [0.0, 0.0, 0.9,", 1))
    made["gcode_latin1"].write_bytes("G90\n; déjà vu\nG1 X0.01 F600\n".encode("latin-1"))
    made["gcode_utf16"].write_bytes("G90\nG1 X0.01 F600\n".encode("utf-16"))
    made["gcode_tension"].write_text("G90\nM100 P2\n")
    made["gcode_ruckig"].write_text("G20 G1 X0.0000001 F0.001\n")
    made["not_a_bag"].write_bytes(b"not an mcap file\n" * 100)
    made["empty_mcap"].write_bytes(b"")
    return made


def expand(argv, files):
    return [re.sub(r"\{(\w+)\}", lambda m: str(files[m.group(1)]), a) for a in argv]


# (argv, what the error must name: a file key in {braces} or the literal text)
ROBOT = [
    (["robot", "{missing}"], "{missing}"),
    (["robot", "{directory}"], "{directory}"),
    (["robot", "{fifo}"], "{fifo}"),
    (["robot", "{utf16}"], "{utf16}"),
    (["robot", "{latin1}"], "{latin1}"),
    (["robot", "{binary}"], "{binary}"),
    (["robot", "{empty}"], "{empty}"),
    (["robot", "{invalid_yaml}"], "{invalid_yaml}"),
    (["robot", "{yaml_list}"], "{yaml_list}"),
    (["robot", "{deep_yaml}"], "{deep_yaml}"),
    (["robot", "{duplicate_key}"], "{duplicate_key}"),
    (["robot", "{robot_home_outside}"], "{robot_home_outside}"),
    (["robot", "no_such_robot"], "no_such_robot"),
]
PROGRAM = [
    (["program", "check", "{missing}"], "{missing}"),
    (["program", "check", "{gcode_directory}"], "{gcode_directory}"),
    (["program", "check", "{gcode_fifo}"], "{gcode_fifo}"),
    (["program", "check", "{gcode_latin1}"], "{gcode_latin1}"),
    (["program", "check", "{gcode_utf16}"], "{gcode_utf16}"),
    (["program", "check", "{gcode_tension}"], "{gcode_tension}"),
    (["program", "check", "{gcode_ruckig}"], "{gcode_ruckig}"),
    (["program", "check", "rectangle", "--robot", "{utf16}"], "{utf16}"),
    (["program", "check", "rectangle", "--robot", "{directory}"], "{directory}"),
    (["program", "check", "rectangle", "--payload", "-1"], "payload"),
    (["program", "check", "rectangle", "--payload", "nan"], "payload"),
    (["program", "check", "rectangle", "--payload", "inf"], "payload"),
    (["program", "check", "rectangle", "--payload", "heavy"], "--payload"),
    # a program that cannot be read is refused before the graph is asked for
    (["program", "run", "{gcode_directory}", "--server-timeout", "0"], "{gcode_directory}"),
    (["program", "run", "{gcode_latin1}", "--server-timeout", "0"], "{gcode_latin1}"),
    (["program", "run", "{gcode_fifo}", "--server-timeout", "0"], "{gcode_fifo}"),
]
PARAM_LOAD = [  # the file is read before the graph is asked for the node
    (["param", "load", "/no_node", "{missing}"], "{missing}"),
    (["param", "load", "/no_node", "{directory}"], "{directory}"),
    (["param", "load", "/no_node", "{fifo}"], "{fifo}"),
    (["param", "load", "/no_node", "{utf16}"], "{utf16}"),
    (["param", "load", "/no_node", "{latin1}"], "{latin1}"),
    (["param", "load", "/no_node", "{binary}"], "{binary}"),
    (["param", "load", "/no_node", "{invalid_yaml}"], "{invalid_yaml}"),
    (["param", "load", "/no_node", "{yaml_list}"], "{yaml_list}"),
    (["param", "load", "/no_node", "{deep_yaml}"], "{deep_yaml}"),
    (["param", "load", "/no_node", "{params_list}"], "{params_list}"),
    (["param", "load", "/no_node", "{params_huge_int}"], "{params_huge_int}"),
]
LAUNCH = [  # --show: parse the file and print the graph, start nothing
    (["launch", "{missing}", "--show"], "{missing}"),
    (["launch", "{directory}", "--show"], "{directory}"),
    (["launch", "{fifo}", "--show"], "{fifo}"),
    (["launch", "{utf16}", "--show"], "{utf16}"),
    (["launch", "{latin1}", "--show"], "{latin1}"),
    (["launch", "{binary}", "--show"], "{binary}"),
    (["launch", "{invalid_yaml}", "--show"], "{invalid_yaml}"),
    (["launch", "{yaml_list}", "--show"], "{yaml_list}"),
    (["launch", "{deep_yaml}", "--show"], "{deep_yaml}"),
    (["launch", "{launch_no_list}", "--show"], "{launch_no_list}"),
]
BAG = [
    (["bag", "info", "{missing}"], "{missing}"),
    (["bag", "info", "{directory}"], "{directory}"),
    (["bag", "reindex", "{missing}"], "{missing}"),
    (["bag", "reindex", "{directory}"], "{directory}"),
    (["bag", "play", "{missing}"], "{missing}"),
    (["bag", "play", "{directory}"], "{directory}"),
    (["plot", "{missing}"], "{missing}"),
]
IDENTIFY = [([ "identify", what, "{" + bad + "}"], "{" + bad + "}")
            for what in ("friction", "drive", "mass", "stiffness", "settlement", "eigenfrequency")
            for bad in ("missing", "directory", "latin1")]
ANALYZE = [
    (["analyze", "energy", "{missing}", "--robot", "ipanema3_mini"], "{missing}"),
    (["analyze", "energy", "--trajectory", "rectangle", "--robot", "ipanema3_mini", "--payload", "-1"], "payload"),
    (["analyze", "energy", "--trajectory", "rectangle", "--robot", "ipanema3_mini", "--v-max", "nan"], "velocity limit"),
    (["analyze", "energy", "--trajectory", "rectangle", "--robot", "ipanema3_mini", "--j-max", "inf"], "jerk limit"),
    (["analyze", "energy", "--trajectory", "rectangle", "--robot", "{utf16}"], "{utf16}"),
    (["analyze", "force-distribution", "--robot", "{duplicate_key}"], "{duplicate_key}"),
    (["analyze", "force-distribution", "--robot", "ipanema3_mini", "--mass", "nan"], "mass"),
    (["analyze", "force-distribution", "--robot", "ipanema3_mini", "--step", "0"], "step"),
    (["analyze", "eigenfrequencies", "--robot", "ipanema3_mini", "--step", "-1"], "step"),
    (["analyze", "eigenfrequencies", "--robot", "ipanema3_mini", "--payloads", "nan"], "payload"),
    (["analyze", "stability", "--robot", "{latin1}"], "{latin1}"),
    (["analyze", "stability", "--robot", "ipanema3_mini", "--payload", "nan"], "payload"),
    (["analyze", "energy", "--trajectory", "{gcode_latin1}", "--robot", "ipanema3_mini"], "{gcode_latin1}"),
    (["analyze", "energy", "--trajectory", "{gcode_directory}", "--robot", "ipanema3_mini"],
     "{gcode_directory}: is a directory"),
    (["analyze", "stability", "--robot", "ipanema3_mini", "--params", "{utf16}"], "{utf16}"),
    (["analyze", "stability", "--robot", "ipanema3_mini", "--params", "{yaml_list}"], "{yaml_list}"),
    (["analyze", "stability", "--robot", "ipanema3_mini", "--damping-time", "nan"], "damping"),
    (["analyze", "stability", "--robot", "ipanema3_mini", "--pade-order", "-1"], "pade"),
    (["analyze", "eigenfrequencies", "--robot", "ipanema3_mini", "--z", "nan"], "z"),
    (["analyze", "force-distribution", "--robot", "ipanema3_mini", "--speed", "-1"], "speed"),
]


def in_process(argv, capsys) -> tuple[int, str, str]:
    try:
        code = cli.main(argv)
    except SystemExit as exc:          # argparse: exit 2 with the usage and the argument
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def check_refused(code, out: str, err: str, named: str) -> None:
    assert code in (1, 2), (code, out, err)
    assert "Traceback" not in err and "Traceback" not in out
    # the tool's own errors are one line on stderr ("cdpr VERB: error: ..."); argparse's end its
    # usage; a program's diagnostics are file:line:col lines on stdout (like a compiler's)
    lines = err.strip().splitlines() if err.strip() else out.strip().splitlines()
    message = lines[-1]
    assert named in message, (named, out, err)
    if code == 1 and err.strip():              # progress lines may come before it
        assert [line for line in lines if line.startswith("cdpr ")] == [message], err


# numbers a bag or a client cannot wait for, or that overflow its nanosecond times; patterns that
# do not compile (issue 28: `--start-offset 1e300` answered "cannot convert float infinity to
# integer", `--clock 1e300` spun for ever ignoring SIGTERM, `-x (` an re error naming no argument)
ARGUMENTS = [(["bag", "play", "BAG", option, value], option)
             for option, value in (("--start-offset", "1e300"), ("--delay", "1e300"), ("--delay", "-1"),
                                   ("--wait-for-subscribers", "inf"), ("--clock", "1e300"), ("--clock", "-5"),
                                   ("-r", "nan"))] + \
    [(["bag", "record", "-a", option, value], option)
     for option, value in (("--stop-after", "1e300"), ("--stop-after", "-1"), ("-d", "1e300"), ("-x", "("),
                           ("-x", "[a-"))] + \
    [(["program", "run", "rectangle", option, value], option)
     for option, value in (("--timeout", "nan"), ("--timeout", "-1"), ("--timeout", "0"),
                           ("--server-timeout", "-1"), ("--server-timeout", "inf"))]
ARGUMENTS += [(["param", "list", "--spin-time", "nan"], "--spin-time"),
              (["param", "get", "/x", "y", "--timeout", "-1"], "--timeout"),
              (["param", "set", "/x", "y", "1", "--timeout", "inf"], "--timeout")]

# fixed by the bag reader's work (issue 28): a file that is no MCAP is refused naming it
BAG_READER = [(["bag", "info", "{not_a_bag}"], "{not_a_bag}"), (["bag", "info", "{empty_mcap}"], "{empty_mcap}"),
              (["bag", "reindex", "{not_a_bag}"], "{not_a_bag}")] + \
    [(["identify", what, "{" + bad + "}"], "{" + bad + "}")
     for what in ("friction", "drive", "mass", "stiffness", "settlement", "eigenfrequency")
     for bad in ("empty_mcap", "not_a_bag")]


@pytest.mark.parametrize("argv, named",
                         ROBOT + PROGRAM + PARAM_LOAD + LAUNCH + BAG + IDENTIFY + ANALYZE + BAG_READER + ARGUMENTS,
                         ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_bad_input_is_refused_in_one_line_naming_it(files, capsys, argv, named):
    check_refused(*in_process(expand(argv, files), capsys), expand([named], files)[0])


def cdpr(*argv, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cdpr_tools.cli", *argv], env=subprocess_env(), text=True,
                          timeout=SUBPROCESS_TIMEOUT, **kwargs)


@pytest.mark.parametrize("argv, named", [
    (["program", "run", "{gcode_latin1}", "--server-timeout", "0"], "{gcode_latin1}"),
    (["robot", "{fifo}"], "{fifo}"),
    (["param", "load", "/no_node", "{yaml_list}"], "{yaml_list}"),
    (["launch", "{deep_yaml}"], "{deep_yaml}"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_bad_input_as_a_command_ends_with_a_status_not_a_signal(files, argv, named):
    run = cdpr(*expand(argv, files), capture_output=True)
    check_refused(run.returncode, run.stdout, run.stderr, expand([named], files)[0])


@pytest.mark.parametrize("argv", [["robot", "ipanema3"], ["program", "list"], ["robot"]])
def test_a_closed_pipe_ends_quietly_as_coreutils_do(argv):
    """`cdpr robot ipanema3 | head -0`: the reader is gone before the first line is written."""
    process = subprocess.Popen([sys.executable, "-m", "cdpr_tools.cli", *argv], env=subprocess_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()                      # no reader left: every write gets EPIPE
    try:
        err = process.stderr.read().decode()
        code = process.wait(timeout=SUBPROCESS_TIMEOUT)
    finally:
        process.kill()
        process.wait()
        process.stderr.close()
    assert err == "" and code == 141            # 128 + SIGPIPE, the status of `yes | head -0`


@pytest.mark.parametrize("text", ["!!binary_AAA", "{a: 1", "[1, 2", "[" * 2000])
def test_a_parameter_value_that_is_not_yaml_is_a_string(text):
    """`cdpr param set NODE NAME VALUE`: VALUE is read as YAML, as `ros2 param set` does; what does not
    parse is the text itself (issue 28: a tag or scanner error escaped as a YAML caret message)."""
    from rcl_interfaces.msg import ParameterType
    from cdpr_tools.param_cmd import parameter_value
    value = parameter_value(text)
    assert value.type == ParameterType.PARAMETER_STRING and value.string_value == text
