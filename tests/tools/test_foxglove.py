"""Live view: the composed main graph (IPAnema 3 Mini, the default simulated plant), started with
`cdpr launch`, seen through the Foxglove WebSocket protocol, as the Foxglove app sees it: a WebSocket client subscribes, receives
and decodes /winch/state and the marker topic with the advertised ros2msg schemas (mcap_ros2, an
independent CDR decoder), reads and sets parameters; the markers are drawn to a PNG."""
import json
import signal
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import yaml
from mcap_ros2._dynamic import generate_dynamic
from rclpy import node as rclpy_node
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from websockets.sync.client import connect

from cdpr_control.model.robot import load_robot
from cdpr_control.ros.runner import spin
from cdpr_test_nodes.graph import wait_for
from cdpr_tools.bag.schema import message_definition
from cdpr_tools.marker_plot import Scene, plot_markers
from cdpr_tools.nodes.foxglove_bridge import FoxgloveBridge
from cdpr_tools.ros_graph import new_context
from cdpr_tools.share import package_share
from cdpr_tools.view_cmd import layout_file

ROBOT = "ipanema3_mini"
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
MESSAGE_DATA = 0x01  # binary opcode: uint32 subscription id, uint64 log time [ns], payload


class Client:
    """The client side of the Foxglove WebSocket protocol, enough to subscribe and to use parameters."""

    def __init__(self, ws):
        self.ws = ws
        self.channels: dict[str, dict] = {}
        self.decoders: dict[int, object] = {}
        self.messages: dict[int, list] = {}
        self.replies: dict[str, dict] = {}

    def receive(self, until, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not until():
            remaining = deadline - time.monotonic()
            assert remaining > 0, (f"timed out waiting on the Foxglove server: {len(self.channels)} channels, "
                                   f"messages per subscription {({k: len(v) for k, v in self.messages.items()})}")
            try:
                data = self.ws.recv(timeout=min(remaining, 1.0))
            except TimeoutError:
                continue
            if isinstance(data, bytes):
                assert data[0] == MESSAGE_DATA
                sub_id, log_time = struct.unpack_from("<IQ", data, 1)
                self.messages.setdefault(sub_id, []).append((log_time, self.decoders[sub_id](data[13:])))
                continue
            reply = json.loads(data)
            if reply["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in reply["channels"]})
            elif "id" in reply:
                self.replies[reply["id"]] = reply

    def subscribe(self, sub_id: int, topic: str) -> None:
        channel = self.channels[topic]
        self.decoders[sub_id] = generate_dynamic(channel["schemaName"], channel["schema"])[channel["schemaName"]]
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub_id, "channelId": channel["id"]}]}))

    def unsubscribe(self, *sub_ids: int) -> None:
        self.ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": list(sub_ids)}))

    def request(self, op: str, request_id: str, **fields) -> dict:
        self.ws.send(json.dumps({"op": op, "id": request_id, **fields}))
        self.receive(lambda: request_id in self.replies)
        return self.replies.pop(request_id)


@pytest.fixture(scope="module")
def live():
    """The composed graph in a process of its own (`cdpr launch`), the bridge in this one, as with
    `cdpr view`: a lockstep graph keeps its process's GIL busy, so the bridge does not share it."""
    graph = package_share("cdpr_tools") / "graphs" / "closed_loop.yaml"
    launch = subprocess.Popen([sys.executable, "-m", "cdpr_tools.cli", "launch", str(graph), f"robot:={ROBOT}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    context = new_context()
    bridge = FoxgloveBridge(context=context, parameter_overrides=[Parameter("port", value=0),
                                                                  Parameter("discovery_period", value=0.1)])
    executor = EventsExecutor(context=context)
    executor.add_node(bridge)
    stop = threading.Event()
    thread = threading.Thread(target=spin, args=(executor, stop), daemon=True)
    thread.start()
    try:
        with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=SUBPROTOCOLS, open_timeout=10) as ws:
            yield launch, bridge, Client(ws)
    finally:
        stop.set()
        thread.join(5)
        bridge.destroy_node()
        context.try_shutdown()
        launch.send_signal(signal.SIGINT)
        _, err = launch.communicate(timeout=60)
    assert launch.returncode == 0, err[-2000:]


def test_winch_state_and_markers_arrive_and_decode_with_the_bag_schema(live, tmp_path):
    launch, bridge, client = live
    robot = load_robot(ROBOT)
    client.receive(lambda: {"/winch/state", "/visualization/markers"} <= set(client.channels))
    for topic, channel in client.channels.items():  # the schemas the bag writer stores
        assert (channel["encoding"], channel["schemaEncoding"]) == ("cdr", "ros2msg"), topic
        assert channel["schema"] == message_definition(channel["schemaName"]), topic
    assert client.channels["/winch/state"]["schemaName"] == "sensor_msgs/msg/JointState"
    assert client.channels["/visualization/markers"]["schemaName"] == "visualization_msgs/msg/MarkerArray"
    client.subscribe(1, "/winch/state")
    client.subscribe(2, "/visualization/markers")
    scene = Scene()  # the newest marker per (ns, id), as Foxglove keeps them

    def markers_complete() -> bool:  # frame and anchors come once a second
        for _, array in client.messages.pop(2, []):
            scene.add(array)
        return "frame" in scene.namespaces and "cables" in scene.namespaces

    def running(m) -> bool:  # past the start-up handshake (the state of stamp 0 repeated)
        return m.header.stamp.sec > 0 or m.header.stamp.nanosec >= 100_000_000

    client.receive(lambda: sum(running(m) for _, m in client.messages.get(1, [])) >= 20 and markers_complete())

    states = [m for _, m in client.messages[1] if running(m)]
    stamps = [s.header.stamp.sec * 10**9 + s.header.stamp.nanosec for s in states]
    assert all(len(s.position) == robot.m and np.all(np.isfinite(s.position)) for s in states)
    assert all(b > a for a, b in zip(stamps, stamps[1:]))  # the 1 kHz loop, in order
    assert all(np.diff(stamps) % 1_000_000 == 0)  # whole control periods of 1 ms

    assert scene.namespaces == {"frame", "anchors", "pulleys", "cables", "platform", "setpoint", "wrench"}
    assert sorted(i for ns, i in scene.markers if ns == "pulleys") == list(range(robot.m))  # a disc per pulley
    assert all(m.header.frame_id == "base" for m in scene.markers.values())
    markers = {ns: m for (ns, i), m in scene.markers.items() if i == 0}
    anchors = np.array([(p.x, p.y, p.z) for p in markers["anchors"].points])
    np.testing.assert_allclose(anchors, robot.a, atol=1e-12)
    cables = markers["cables"]
    assert len(cables.points) == 2 * robot.m and len(cables.colors) == 2 * robot.m
    ends = np.array([(p.x, p.y, p.z) for p in cables.points]).reshape(robot.m, 2, 3)
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    assert np.all((length > 0.1) & (length < np.linalg.norm(robot.frame_size)))
    # pretensioned at minimal tension: forces within their limits, so no cable is drawn magenta
    assert not any(c.r == 1.0 and c.b == 1.0 and c.g == 0.0 for c in cables.colors)

    png = plot_markers(scene, tmp_path / "markers.png")
    assert png.stat().st_size > 10_000
    # leave nothing running for the next test: a 1 kHz stream still forwarded queues in the
    # bridge's executor ahead of its parameter services' answers (on a loaded machine, past their timeout)
    client.unsubscribe(1, 2)
    wait_for(lambda: bridge.subscribed_topics() == [], what="the bridge to drop its subscriptions")


def test_parameters_read_and_set_through_the_protocol(live):
    launch, bridge, client = live
    name = "/cable_force_controller.K_p"
    params = yaml.safe_load((package_share("cdpr_control") / "params" / f"{ROBOT}.yaml").read_text())
    k_p = params["cable_force_controller"]["ros__parameters"]["K_p"]
    got = client.request("getParameters", "get", parameterNames=[name])["parameters"]
    assert got == [{"name": name, "type": "float64", "value": k_p}]
    everything = client.request("getParameters", "all", parameterNames=[])["parameters"]
    assert {"/ospc.K_p", "/force_distribution.tension_level", name} <= {p["name"] for p in everything}
    assert not any(p["name"].startswith("/foxglove_bridge.") for p in everything)

    reply = client.request("setParameters", "set", parameters=[{"name": name, "value": 0.5}])
    assert reply["parameters"][0]["value"] == 0.5
    reply = client.request("setParameters", "bad", parameters=[{"name": name, "value": "fast"}])
    assert reply["parameters"][0]["value"] == 0.5  # refused, kept
    got = client.request("getParameters", "again", parameterNames=[name])["parameters"]
    assert got[0]["value"] == 0.5  # as the node holds it


def test_the_shipped_layout_shows_topics_the_graph_publishes(live):
    launch, bridge, client = live
    layout = json.loads(layout_file().read_text())
    panels = layout["configById"]
    assert "3D!cdpr" in panels and panels["3D!cdpr"]["topics"]["/visualization/markers"]["visible"]
    used = {"/visualization/markers", panels["RawMessages!cdpr"]["topicPath"], panels["DiagnosticSummary!cdpr"]["topicToRender"]}
    used |= {p["value"].split(".")[0] for c in panels.values() for p in c.get("paths", [])}
    client.receive(lambda: used <= set(client.channels))

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])
    assert sorted(leaves(layout["layout"])) == sorted(panels)


def test_the_bridge_subscribes_only_while_a_client_watches():
    """Unwatched the bridge costs the graph nothing: topics are advertised, but the ROS subscription
    exists only while a client subscribes to the channel, and is dropped when the last one
    unsubscribes or disconnects (the publisher's matched-subscription count, over DDS, says so)."""
    from cdpr_test_nodes.graph import Spinner

    graph, view = Spinner(), Spinner()
    try:
        talker = graph.add(_Talker)
        bridge = view.add(FoxgloveBridge, parameter_overrides=[Parameter("port", value=0),
                                                               Parameter("discovery_period", value=0.1),
                                                               Parameter("topics", value=["/lazy_a", "/lazy_b"])])
        pub_a, pub_b = talker.pubs
        with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=SUBPROTOCOLS, open_timeout=10) as ws:
            client = Client(ws)
            client.receive(lambda: {"/lazy_a", "/lazy_b"} <= set(client.channels))
            assert bridge.subscribed_topics() == []
            assert pub_a.get_subscription_count() == 0 and pub_b.get_subscription_count() == 0

            client.subscribe(1, "/lazy_a")
            client.receive(lambda: len(client.messages.get(1, [])) >= 3)
            assert all(isinstance(m.data, str) and m.data.startswith("a") for _, m in client.messages[1])
            assert bridge.subscribed_topics() == ["/lazy_a"]
            wait_for(lambda: pub_a.get_subscription_count() == 1, what="the bridge's subscription to /lazy_a")
            assert pub_b.get_subscription_count() == 0

            ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [1]}))
            wait_for(lambda: bridge.subscribed_topics() == [], what="the subscription dropped")
            wait_for(lambda: pub_a.get_subscription_count() == 0, what="/lazy_a unmatched")

            client.subscribe(2, "/lazy_b")
            wait_for(lambda: bridge.subscribed_topics() == ["/lazy_b"], what="the subscription to /lazy_b")
        # the client disconnected: its channels are unsubscribed
        wait_for(lambda: bridge.subscribed_topics() == [], what="the subscription dropped on disconnect")
        wait_for(lambda: pub_b.get_subscription_count() == 0, what="/lazy_b unmatched")
    finally:
        for spinner in (view, graph):
            spinner.close()


class _Talker(rclpy_node.Node):
    """Publishes /lazy_a and /lazy_b (std_msgs/String) every 20 ms."""

    def __init__(self, **kwargs):
        from std_msgs.msg import String

        super().__init__("lazy_talker", **kwargs)
        self.pubs = (self.create_publisher(String, "/lazy_a", 10), self.create_publisher(String, "/lazy_b", 10))
        self.k = 0

        def tick():
            self.k += 1
            self.pubs[0].publish(String(data=f"a{self.k}"))
            self.pubs[1].publish(String(data=f"b{self.k}"))
        self.create_timer(0.02, tick)


SERVICE_CALL_REQUEST, SERVICE_CALL_RESPONSE, CLIENT_MESSAGE_DATA = 0x02, 0x03, 0x01


def test_services_and_client_publishing_reach_the_graph():
    """Foxglove's Service Call panel calls a ROS service of the graph through the bridge (CDR both
    ways, ros2msg schemas from the .srv file), and its Publish panel publishes on a ROS topic
    (clientPublish): a std_srvs/SetBool server flips, a std_msgs/String arrives."""
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import String
    from std_srvs.srv import SetBool

    from cdpr_test_nodes.graph import Collector, Spinner

    graph, view = Spinner(), Spinner()
    try:
        served = []
        server = graph.add(Collector, topics={"/from_foxglove": String})

        def set_bool(request, response):
            served.append(request.data)
            response.success, response.message = True, f"now {request.data}"
            return response
        server.create_service(SetBool, "/test_switch", set_bool)
        bridge = view.add(FoxgloveBridge, parameter_overrides=[Parameter("port", value=0),
                                                               Parameter("discovery_period", value=0.1)])
        with connect(f"ws://127.0.0.1:{bridge.port}", subprotocols=SUBPROTOCOLS, open_timeout=10) as ws:
            services, responses = {}, []
            deadline = time.monotonic() + 30
            while "/test_switch" not in services:
                assert time.monotonic() < deadline, f"no /test_switch among {sorted(services)}"
                try:
                    data = ws.recv(timeout=1.0)
                except TimeoutError:
                    continue
                if isinstance(data, str) and json.loads(data)["op"] == "advertiseServices":
                    services.update({s["name"]: s for s in json.loads(data)["services"]})
            service = services["/test_switch"]
            assert service["type"] == "std_srvs/srv/SetBool"
            assert service["request"]["schemaEncoding"] == "ros2msg" and "bool data" in service["request"]["schema"]
            assert "string message" in service["response"]["schema"]
            payload = serialize_message(SetBool.Request(data=True))
            ws.send(struct.pack("<BIII", SERVICE_CALL_REQUEST, service["id"], 7, 3) + b"cdr" + payload)
            while not responses:
                data = ws.recv(timeout=10.0)
                if isinstance(data, bytes) and data[0] == SERVICE_CALL_RESPONSE:
                    responses.append(data)
            service_id, call_id, length = struct.unpack_from("<III", responses[0], 1)
            assert (service_id, call_id, responses[0][13:13 + length]) == (service["id"], 7, b"cdr")
            reply = deserialize_message(responses[0][13 + length:], SetBool.Response)
            assert (reply.success, reply.message, served) == (True, "now True", [True])

            ws.send(json.dumps({"op": "advertise", "channels": [
                {"id": 5, "topic": "/from_foxglove", "encoding": "cdr", "schemaName": "std_msgs/msg/String"}]}))
            wait_for(lambda: bridge.client_publishers, what="the bridge's publisher for the client channel")
            wait_for(lambda: server.count("/from_foxglove") > 0 or
                     ws.send(struct.pack("<BI", CLIENT_MESSAGE_DATA, 5) + serialize_message(String(data="hi"))),
                     what="the client's message on /from_foxglove")
            assert {m.data for m in server.messages("/from_foxglove")} == {"hi"}
        wait_for(lambda: not bridge.client_publishers, what="the client's publisher removed on disconnect")
    finally:
        for spinner in (view, graph):
            spinner.close()
