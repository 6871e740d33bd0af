"""A slow period of a composed lockstep graph is not a stopped simulator (its own module: one graph
per ROS domain, and the module's domain is its own)."""
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher, NodeSpec
from cdpr_tools.launch_file import load_launch_file

from test_program_run_cli import PROGRAM, check_done, program_run


def test_a_slow_composed_period_is_not_a_stopped_simulator(tmp_path):
    """Lockstep, composed: a period that takes longer than ``state_timeout`` of wall time (here a node
    blocking 0.3 s every 200th winch/state against a 0.2 s timeout; on a loaded machine, a process
    descheduled for seconds) is slow, not stopped: the program runs to the end. (The interpreter
    failed it with "no winch/state for 0.2 s" before it learnt to wait, as the simulator does, while
    the graph in its process still computes a period.)"""
    description = load_launch_file(GRAPH, {"robot": "ipanema3_mini"})
    interpreter = next(s for s in description.nodes if s.module.endswith("gcode_interpreter"))
    interpreter.parameters.append({"state_timeout": 0.2})
    description.nodes.append(NodeSpec(module="cdpr_test_nodes.slow_period"))
    with Launcher(description, mode="composed") as launch:
        slow = next(n for n in launch.nodes if n.get_name() == "slow_period")
        path = tmp_path / "out_and_back.gcode"
        path.write_text(PROGRAM)
        check_done(program_run(str(path)), "out_and_back")
        assert slow.paused >= 3, slow.paused    # the program ran through several slow periods
        assert launch.errors == []
