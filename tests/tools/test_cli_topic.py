"""`cdpr topic` on a running talker: list, info, echo, hz, pub, and errors that name what exists."""
import pytest
import yaml
from std_msgs.msg import Header, String

from cdpr_test_nodes.graph import Collector, Spinner, wait_for
from cdpr_test_nodes.talker import Talker
from cdpr_tools import cli
from cdpr_tools.topic_cmd import format_rate

TOPIC = "/topic_test/chatter"


@pytest.fixture(scope="module")
def graph():
    spinner = Spinner()
    spinner.add(Talker, cli_args=["--ros-args", "-r", "__node:=topic_talker", "-r", f"chatter:={TOPIC}",
                                  "-p", "rate:=50.0", "-p", "greeting:=hi"])
    yield spinner
    spinner.close()


def cdpr(capfd, *argv) -> tuple[int, str, str]:
    rc = cli.main(["topic", *argv])
    out, err = capfd.readouterr()
    return rc, out, err


def test_list_and_info(graph, capfd):
    rc, out, _ = cdpr(capfd, "list", "-t", "--spin-time", "1")
    assert rc == 0 and f"{TOPIC} [std_msgs/msg/String]" in out.splitlines()
    rc, out, _ = cdpr(capfd, "info", TOPIC, "-v", "--timeout", "15")
    assert rc == 0
    assert out.startswith("Type: std_msgs/msg/String\nPublisher count: 1\n")
    assert "Node name: topic_talker" in out and "Reliability: RELIABLE" in out


def test_echo_prints_yaml_documents(graph, capfd):
    rc, out, _ = cdpr(capfd, "echo", TOPIC, "--count", "3", "--timeout", "15")
    assert rc == 0
    docs = [d for d in out.split("---\n") if d.strip()]
    assert len(docs) == 3
    numbers = [int(yaml.safe_load(d)["data"].split()[1]) for d in docs]
    assert numbers == list(range(numbers[0], numbers[0] + 3)) and out.startswith("data: hi ")
    rc, out, _ = cdpr(capfd, "echo", TOPIC, "std_msgs/msg/String", "--once", "--field", "data")
    assert rc == 0 and out.startswith("hi ") and out.endswith("---\n")


def test_hz_measures_the_rate(graph, capfd):
    rc, out, _ = cdpr(capfd, "hz", TOPIC, "--duration", "2", "--timeout", "15")
    assert rc == 0 and out.startswith("average rate: ")
    rate = float(out.split()[2])
    assert 10.0 < rate < 250.0  # 50 Hz nominal; loose, the machine is shared


def test_rate_report_format():
    text = format_rate([0, 10_000_000, 20_000_000, 30_000_000], "wall time")
    assert text == "average rate: 100.000 (wall time)\n\tmin: 0.010s max: 0.010s std dev: 0.00000s window: 3"
    assert format_rate([5], "wall time") == "no new messages"


def test_pub_delivers_messages_with_now_stamps(graph, capfd):
    collector = graph.add(Collector, topics={"/topic_test/pub": String, "/topic_test/header": Header})
    rc, out, _ = cdpr(capfd, "pub", "/topic_test/pub", "std_msgs/msg/String", "{data: yo}", "--times", "2", "-r", "20")
    assert rc == 0 and "publishing #2: std_msgs.msg.String(data='yo')" in out
    wait_for(lambda: collector.count("/topic_test/pub") == 2, what="published messages")
    assert [m.data for m in collector.messages("/topic_test/pub")] == ["yo", "yo"]
    rc, _, _ = cdpr(capfd, "pub", "/topic_test/header", "std_msgs/msg/Header", "{stamp: now, frame_id: base}", "-1")
    wait_for(lambda: collector.count("/topic_test/header") == 1, what="header")
    header = collector.messages("/topic_test/header")[0]
    assert header.frame_id == "base" and header.stamp.sec > 1_600_000_000


def test_errors_name_what_exists(graph, capfd):
    rc, _, err = cdpr(capfd, "echo", "/topic_test/nothing", "--timeout", "4")
    assert rc == 1 and "topic /topic_test/nothing not found; topics:" in err and TOPIC in err
    rc, _, err = cdpr(capfd, "pub", "/x", "std_msgs/msg/String", "{dat: 1}", "-1")
    assert rc == 1 and "has no field 'dat'; fields: data" in err
    rc, _, err = cdpr(capfd, "pub", "/x", "std_msgs/msg/Strin", "{}", "-1")
    assert rc == 1 and "std_msgs/msg has" in err and "String" in err
