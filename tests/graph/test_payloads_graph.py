"""Type adaptation in the shipped graph (graphs/closed_loop.yaml, IPAnema 3 Mini, composed, lockstep):
with no subscriber outside the process and no recorder, the nodes pass payloads only and no ROS
message is built from one (cdpr_control.ros.adapted; issue 26: a subscription that is not
``adapted`` has every payload of its topic built into a message, about 6 us a period for the
admittance controller's state, which the interpreter takes as its set-point source)."""
from cdpr_control.ros import adapted
from cdpr_test_nodes.graph import wait_for
from cdpr_tools.demo_cmd import GRAPH
from cdpr_tools.launch import Launcher
from cdpr_tools.launch_file import load_launch_file

PERIODS = 200


def test_no_payload_becomes_a_message_while_the_composed_graph_holds(monkeypatch):
    built = []
    to_msg = adapted.Payload.to_msg

    def counted(self):
        built.append(type(self).__name__)
        return to_msg(self)
    description = load_launch_file(GRAPH, {"robot": "ipanema3_mini"})
    with Launcher(description, mode="composed") as launch:
        sim = next(n for n in launch.nodes if n.get_name() == "winch_platform_sim").sim
        wait_for(lambda: sim.steps > 50, timeout=120.0, what="the loop to run")
        monkeypatch.setattr(adapted.Payload, "to_msg", counted)
        start = sim.steps
        wait_for(lambda: sim.steps >= start + PERIODS, timeout=120.0, what=f"{PERIODS} periods")
        monkeypatch.undo()
        errors = list(launch.errors)
    assert not errors
    assert not built, f"messages built from payloads in {PERIODS} periods: {sorted(set(built))}"
