"""`cdpr param` against a running node, through the standard rcl_interfaces parameter services."""
import subprocess
import sys

import pytest
import yaml
from rclpy.parameter import Parameter

from cdpr_test_nodes.graph import Spinner, subprocess_env
from cdpr_test_nodes.talker import Talker
from cdpr_tools import cli
from cdpr_tools.param_cmd import parameters_for_node

NAME = "param_talker"


@pytest.fixture(scope="module")
def talker():
    spinner = Spinner()
    node = spinner.add(Talker, cli_args=["--ros-args", "-r", f"__node:={NAME}"])
    yield node
    spinner.close()


def cdpr(capfd, *argv) -> tuple[int, str, str]:
    rc = cli.main(["param", *argv, "--timeout", "15"])
    out, err = capfd.readouterr()
    return rc, out, err


def test_set_changes_the_node_and_get_reads_it_back(talker, capfd):
    assert cdpr(capfd, "set", NAME, "rate", "5.5") == (0, "Set parameter successful\n", "")
    assert talker.get_parameter("rate").value == 5.5
    assert cdpr(capfd, "get", NAME, "rate")[1] == "Double value is: 5.5\n"
    assert cdpr(capfd, "get", f"/{NAME}", "gains.axes")[1] == "Integer values are: [1, 2, 3]\n"


def test_out_of_range_value_is_refused_with_the_nodes_reason(talker, capfd):
    before = talker.get_parameter("rate").value
    rc, out, err = cdpr(capfd, "set", NAME, "rate", "5000.0")
    assert rc == 1
    assert err.startswith("Setting parameter failed: ") and "out of range" in err and "1000.0" in err
    assert talker.get_parameter("rate").value == before
    rc, _, err = cdpr(capfd, "set", NAME, "frame", "tool")
    assert rc == 1 and "read-only" in err


def test_list_and_describe(talker, capfd):
    rc, out, _ = cdpr(capfd, "list", NAME)
    assert rc == 0 and out.splitlines()[0] == f"/{NAME}:"
    assert {"  rate", "  greeting", "  gains.kp", "  use_sim_time"} <= set(out.splitlines())
    rc, out, _ = cdpr(capfd, "describe", NAME, "rate", "frame")
    assert rc == 0
    assert "Parameter name: rate\n  Type: double\n  Description: publishing rate [Hz]" in out
    assert "Min value: 0.1" in out and "Max value: 1000.0" in out
    assert "Parameter name: frame\n  Type: string\n  Constraints:\n    Read only: true" in out


def test_dump_writes_standard_layout_and_load_restores(talker, capfd, tmp_path):
    rc, out, _ = cdpr(capfd, "dump", NAME)
    dumped = yaml.safe_load(out)
    params = dumped[f"/{NAME}"]["ros__parameters"]
    assert params["gains"] == {"kp": 1.5, "axes": [1, 2, 3]} and params["frame"] == "base"
    path = tmp_path / "params.yaml"
    path.write_text(out)
    talker.set_parameters([Parameter("greeting", value="changed")])
    rc, out, err = cdpr(capfd, "load", NAME, str(path))
    assert rc == 0, err
    assert "Set parameter greeting successful" in out
    assert talker.get_parameter("greeting").value == params["greeting"]


def test_parameter_file_selection(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": {"use_sim_time": True, "rate": 1.0}},
                                    "/talker": {"ros__parameters": {"rate": 2.0, "gains": {"kp": 3.0}}},
                                    "/other": {"ros__parameters": {"rate": 9.0}}}))
    params = parameters_for_node(str(path), "/talker")
    assert {n: v.double_value for n, v in params.items() if n != "use_sim_time"} == {"rate": 2.0, "gains.kp": 3.0}
    assert params["use_sim_time"].bool_value is True
    assert "use_sim_time" not in parameters_for_node(str(path), "/talker", use_wildcard=False)
    with pytest.raises(ValueError, match="entries: /\\*\\*, /other, /talker"):
        parameters_for_node(str(path), "/nobody", use_wildcard=False)


def test_negative_yaml_values_are_values_not_options(talker, capfd):
    # -.inf parses as the value (argparse would take it for an option); the node refuses it by range
    rc, _, err = cdpr(capfd, "set", NAME, "rate", "-.inf")
    assert rc == 1 and "Setting parameter failed" in err and "out of range" in err
    assert cdpr(capfd, "set", NAME, "gains.kp", "-1.0e-3")[0] == 0
    assert talker.get_parameter("gains.kp").value == -1e-3
    assert cdpr(capfd, "set", NAME, "gains.kp", "1.5")[0] == 0


def test_integer_beyond_int64_is_refused_with_the_reason(talker, capfd):
    rc, _, err = cdpr(capfd, "set", NAME, "gains.axes", "[1, 99999999999999999999]")
    assert rc == 1 and "beyond the 64-bit integers" in err and "1e+20" in err
    assert list(talker.get_parameter("gains.axes").value) == [1, 2, 3]


def test_undeclared_parameter_is_named_by_get_and_describe(talker, capfd):
    for verb in ("get", "describe"):
        rc, out, err = cdpr(capfd, verb, NAME, "no_such_param")
        assert rc == 1 and f"node /{NAME} has no parameter no_such_param" in err and "cdpr param list" in err


def test_unknown_node_names_the_running_ones(talker, capfd):
    rc = cli.main(["param", "get", "/no_such_node", "rate", "--timeout", "4"])
    err = capfd.readouterr().err
    assert rc == 1
    assert "node /no_such_node not found; running nodes:" in err and f"/{NAME}" in err


def test_cdpr_command_in_its_own_process(talker):
    """The installed entry point, as a user runs it, sees the node and reads the parameter."""
    result = subprocess.run([sys.executable, "-m", "cdpr_tools.cli", "param", "get", NAME, "gains.kp",
                             "--timeout", "20"], capture_output=True, text=True, env=subprocess_env(), timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout == "Double value is: 1.5\n"
