"""Checking a program against a robot before it runs: plannable, and inside the wrench-feasible
workspace with its payload (2.39)-(2.40); errors name the line like the parser's."""
import numpy as np
import pytest

from cdpr_control import programs
from cdpr_control.motion.gcode import parse_gcode
from cdpr_control.motion.program import GCodeError
from cdpr_control.motion.program_check import check_program
from cdpr_control.model.robot import load_robot
from cdpr_control.model.workspace import feasible_poses, with_platform_mass
from cdpr_tools.cli import main as cdpr


@pytest.fixture(scope="module")
def mini():
    return load_robot("ipanema3_mini")


def test_leaving_the_workspace_names_the_first_line_outside(mini):
    text = "G90 G1 X0 Y0 Z0 F6000\nG1 X100\nG1 X600\nG1 X0"
    with pytest.raises(GCodeError) as err:
        check_program(parse_gcode(text), mini)
    d = err.value.diagnostics[0]
    assert (d.line, d.column) == (3, 1) and "wrench-feasible workspace" in d.message
    # the reported pose (printed to 1 mm; the path is sampled every 1 mm at 0.1 m/s) is at the border
    x_out = np.array([float(d.message.split("x = [")[1].split(",")[0]), 0, 0, 0, 0, 0])
    step = np.array([0.001, 0, 0, 0, 0, 0])
    assert not feasible_poses(mini, (x_out + step)[None])[0]
    assert feasible_poses(mini, (x_out - 2 * step)[None])[0]


def test_payload_shrinks_the_workspace(mini):
    # a pose inside with the platform alone but outside with a heavy payload
    x = np.array([0.3, 0.0, 0.0, 0, 0, 0])
    assert feasible_poses(mini, x[None])[0]
    heavy = next(p for p in (0.5, 1, 2, 4, 8)
                 if not feasible_poses(with_platform_mass(mini, mini.platform.mass + p), x[None])[0])
    text = "G90 G1 X0 F6000\nG1 X300"
    assert check_program(parse_gcode(text), mini) > 0
    with pytest.raises(GCodeError, match="with .* kg payload"):
        check_program(parse_gcode(text), mini, payload=heavy)


@pytest.mark.parametrize("name", programs.names())
def test_every_shipped_program_passes_for_its_robots(name):
    # *_ipanema3 programs are written for the IPAnema 3's 17 m frame (metres of travel); the others suit both
    robots = ["ipanema3"] + ([] if name.endswith("_ipanema3.gcode") else ["ipanema3_mini"])
    for robot in map(load_robot, robots):
        assert check_program(parse_gcode(programs.read(name), start_pose=robot.home), robot) > 0


def test_cli_check_reports_line_col_and_exit_code(tmp_path, capsys):
    bad = tmp_path / "outside.gcode"
    bad.write_text("G90 G1 X0 F6000\nG1 X600\n")
    assert cdpr(["program", "check", str(bad)]) == 1
    assert f"{bad}:2:1: the path leaves" in capsys.readouterr().out
    latin = tmp_path / "latin.gcode"
    latin.write_bytes("G90 G1 X0 F6000\n(caf\xe9)\n".encode("latin-1"))
    assert cdpr(["program", "check", str(latin)]) == 1
    assert f"{latin}:2:" in capsys.readouterr().out
    assert cdpr(["program", "check", "rectangle", "--robot", "ipanema3"]) == 0
    assert "ok for IPAnema 3" in capsys.readouterr().out


def test_run_without_a_graph_says_so_quickly(capfd):
    import time

    t0 = time.monotonic()
    assert cdpr(["program", "run", "rectangle", "--action", "/no_graph_here", "--server-timeout", "1"]) == 1
    assert time.monotonic() - t0 < 10
    assert "no RunProgram action server at /no_graph_here after 1 s: is a graph running?" in capfd.readouterr().err
