"""Node ``foxglove_bridge``: every ROS topic of the graph, live, over the Foxglove WebSocket protocol.

Built on the Foxglove SDK (``foxglove-sdk``). Like the bag recorder, it subscribes to topics as
they appear (serialized, QoS adapted to the publishers' offers) and offers each as a channel with
the schema the bag writer stores (encoding ``ros2msg``, :func:`cdpr_tools.bag.schema.message_definition`)
and the CDR payload as the middleware delivered it (padding cut, :func:`cdpr_tools.bag.cdr.trimmed`),
so Foxglove decodes live data exactly as it decodes our bags. Log times are the node's clock (sim
time with ``use_sim_time``).

Unwatched, it costs the graph nothing: a topic is *advertised* as soon as it appears, but the bridge
subscribes to it over ROS only when the first Foxglove client subscribes to its channel, and drops
that subscription when the last client unsubscribes or disconnects (as Foxglove's own
foxglove_bridge does). With no client connected the bridge has no subscription in the graph, so no
publisher of the loop serializes or sends anything for it.

Parameters of the other nodes are offered too (Foxglove's Parameters panel): ``/node.name``, read
and set through the standard parameter services (rcl_interfaces), so a rejected value keeps the
node's old one, as with ``cdpr param set``. The graph's services (but the parameter services) are
offered to Foxglove's Service Call panel (request and response in CDR, schemas ``ros2msg`` from the
.srv file), e.g. ``/sim/apply_wrench`` and ``/sim/set_payload``; and a client may publish (Foxglove's
Publish panel, capability ``clientPublish``): the bridge creates a ROS publisher of the advertised
type for each channel a client advertises and passes its CDR messages on.

Parameters: ``host``, ``port`` (0: any free port; the bound one is in :attr:`FoxgloveBridge.port`),
``topics`` (empty: all), ``exclude`` (regex), ``include_hidden_topics``, ``discovery_period`` [s].
"""
from __future__ import annotations

import threading

import foxglove
from foxglove.websocket import Capability, ServerListener
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import deserialize_message, serialize_message

from cdpr_control.ros.runner import run_node
from cdpr_tools.bag.cdr import trimmed
from cdpr_tools.bag.schema import ENCODING, message_definition, service_definitions
from cdpr_tools.message_convert import message_class
from cdpr_tools.ros_graph import TopicSelection, adapted_qos

DEFAULT_PORT = 8765  # Foxglove's default for a live connection
# s a node may take to answer a parameter or service request: a composed lockstep graph answers its
# services between slices of its loop, and on a loaded machine (load 22, RTF 0.06) that took over
# 2 s (the old limit: a Foxglove parameter set came back empty); the wait holds one server thread
SERVICE_TIMEOUT = 10.0
DISCOVERY_PERIOD = 0.5  # s between looks for new topics (default of ``discovery_period``)
WATCH_PERIOD = 0.05  # s at most from a client's subscribe to the bridge's ROS subscription


class FoxgloveBridge(Node):
    def __init__(self, **kwargs):
        super().__init__("foxglove_bridge", **kwargs)
        self.declare_parameter("host", "127.0.0.1", ParameterDescriptor(
            description="address to listen on (0.0.0.0: every interface)", read_only=True))
        self.declare_parameter("port", DEFAULT_PORT, ParameterDescriptor(
            description="WebSocket port; 0: any free port", read_only=True))
        self.channels: dict[str, foxglove.Channel] = {}
        self._offered: dict[str, tuple] = {}          # topic -> (message class, forward callback)
        self._raw_subscriptions: dict[str, object] = {}
        self._watchers: dict[str, int] = {}           # topic -> clients subscribed to its channel
        self._watch_lock = threading.Lock()           # the server's threads count, the node's thread subscribes
        self._watch_changed = threading.Event()
        # the EventsExecutor has no guard conditions: a steady timer in the bridge's own process
        # looks at the flag the server's threads set (20 cheap wake-ups a second; nothing in the graph)
        self.create_timer(WATCH_PERIOD, self._subscribe_watched, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._lock = threading.Lock()  # parameter requests come on the server's threads
        self._param_clients: dict[str, AsyncParameterClient] = {}
        self.fox = foxglove.Context()  # channels of this bridge only (several bridges in one process)
        self.service_clients: dict[str, object] = {}   # service name -> rclpy client (None: not offered)
        self.client_publishers: dict[tuple[int, int], object] = {}   # (client id, channel id) -> publisher
        self.server = foxglove.start_server(
            name=f"cdpr {self.get_fully_qualified_name()}", host=self.get_parameter("host").value,
            port=self.get_parameter("port").value,
            capabilities=[Capability.Parameters, Capability.Services, Capability.ClientPublish],
            supported_encodings=["cdr"], server_listener=_Listener(self), context=self.fox)
        self.port = self.server.port
        self.selection = TopicSelection(self, "offer", DISCOVERY_PERIOD, self._offer)
        self.create_timer(self.get_parameter("discovery_period").value, self._offer_services,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"Foxglove WebSocket server on ws://{self.get_parameter('host').value}:{self.port}")

    def _offer(self, topic: str, type_name: str) -> bool:
        try:
            msg_class = message_class(type_name)
            schema = foxglove.Schema(name=type_name, encoding=ENCODING, data=message_definition(type_name).encode())
        except (LookupError, ValueError) as exc:
            self.get_logger().warning(f"not offering {topic}: {exc}")
            return False
        channel = foxglove.Channel(topic, schema=schema, message_encoding="cdr", context=self.fox)
        clock = self.get_clock()

        def forward(data: bytes) -> None:
            if channel.has_sinks():
                channel.log(trimmed(type_name, data), log_time=clock.now().nanoseconds)

        self.channels[topic] = channel
        self._offered[topic] = (msg_class, forward)
        self.get_logger().debug(f"offering {topic} [{type_name}]")
        self._watch_changed.set()     # a client may have subscribed before the topic was offered
        return True

    # -- subscriptions while watched -----------------------------------------------------------------
    def watch(self, topic: str, delta: int) -> None:
        """A client subscribed (+1) to or left (-1) ``topic``'s channel (on a server thread)."""
        with self._watch_lock:
            self._watchers[topic] = max(0, self._watchers.get(topic, 0) + delta)
        self._watch_changed.set()

    def _subscribe_watched(self) -> None:
        """On the node's executor: a ROS subscription for every watched offered topic, none for the others."""
        if not self._watch_changed.is_set():
            return
        self._watch_changed.clear()
        with self._watch_lock:
            watched = {t for t, n in self._watchers.items() if n > 0}
        for topic in list(self._raw_subscriptions):
            if topic not in watched:
                self.destroy_subscription(self._raw_subscriptions.pop(topic))
                self.get_logger().debug(f"unsubscribed {topic}: no client watches it")
        for topic in watched - set(self._raw_subscriptions):
            if topic in self._offered:
                msg_class, forward = self._offered[topic]
                self._raw_subscriptions[topic] = self.create_subscription(
                    msg_class, topic, forward, adapted_qos(self, topic), raw=True)
                self.get_logger().debug(f"subscribed {topic} for a client")

    def subscribed_topics(self) -> list[str]:
        """The topics the bridge subscribes to in the graph now (the watched ones)."""
        return sorted(self._raw_subscriptions)

    # -- services of the graph, for Foxglove's Service Call panel -------------------------------------
    def _offer_services(self) -> None:
        new = []
        for name, types in self.get_service_names_and_types():
            if name in self.service_clients or len(types) != 1 or types[0].startswith("rcl_interfaces/") \
                    or any(part.startswith("_") for part in name.split("/")):
                continue
            try:
                srv_class = message_class(types[0])
                request, response = service_definitions(types[0])
            except (LookupError, ValueError) as exc:
                self.get_logger().warning(f"not offering service {name}: {exc}")
                self.service_clients[name] = None
                continue
            self.service_clients[name] = self.create_client(srv_class, name)
            schema = foxglove.ServiceSchema(
                types[0],
                request=foxglove.MessageSchema(encoding="cdr", schema=foxglove.Schema(
                    name=f"{types[0]}_Request", encoding=ENCODING, data=request.encode())),
                response=foxglove.MessageSchema(encoding="cdr", schema=foxglove.Schema(
                    name=f"{types[0]}_Response", encoding=ENCODING, data=response.encode())))
            new.append(foxglove.Service(name, schema=schema, handler=self._service_handler(name, srv_class)))
        if new:
            self.server.add_services(new)

    def _service_handler(self, name: str, srv_class):
        def handle(request) -> bytes:
            """On a server thread: the CDR request to the ROS service, its response back in CDR."""
            future = self.service_clients[name].call_async(deserialize_message(request.payload, srv_class.Request))
            response = self._call(future)
            if response is None:
                raise RuntimeError(f"{name} did not answer within {SERVICE_TIMEOUT:g} s")
            return serialize_message(response)
        return handle

    # -- messages published by clients (Foxglove's Publish panel) ------------------------------------
    def client_advertised(self, client_id: int, channel) -> None:
        if channel.encoding != "cdr":
            self.get_logger().warning(f"client channel {channel.topic}: encoding {channel.encoding!r} "
                                      f"is not supported (cdr only)")
            return
        try:
            msg_class = message_class(channel.schema_name)
        except (LookupError, ValueError) as exc:
            self.get_logger().warning(f"client channel {channel.topic}: {exc}")
            return
        self.client_publishers[(client_id, channel.id)] = self.create_publisher(msg_class, channel.topic, 10)

    def client_unadvertised(self, client_id: int, channel_id: int) -> None:
        publisher = self.client_publishers.pop((client_id, channel_id), None)
        if publisher is not None:
            self.destroy_publisher(publisher)

    def client_message(self, client_id: int, channel_id: int, data: bytes) -> None:
        publisher = self.client_publishers.get((client_id, channel_id))
        if publisher is not None:
            publisher.publish(data)               # the CDR bytes as they came

    # -- parameters of the graph's nodes ------------------------------------------------------------
    def _client(self, node: str) -> AsyncParameterClient:
        if node not in self._param_clients:
            self._param_clients[node] = AsyncParameterClient(self, node)
        return self._param_clients[node]

    def _call(self, future):
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        if not done.wait(SERVICE_TIMEOUT):
            future.cancel()
            self.get_logger().warning(f"a request got no answer within {SERVICE_TIMEOUT:g} s")
            return None
        return future.result()

    def remote_nodes(self) -> list[str]:
        own = self.get_fully_qualified_name()
        names = [f"{ns.rstrip('/')}/{name}" for name, ns in self.get_node_names_and_namespaces()]
        return sorted(n for n in names if n != own and not any(p.startswith("_") for p in n.split("/")))

    def get_parameters(self, names: list[str]) -> list[foxglove.Parameter]:
        """``/node.param`` values; all parameters of every node when ``names`` is empty."""
        wanted: dict[str, list[str]] = {}
        for full in names:
            node, _, param = full.partition(".")
            wanted.setdefault(node, []).append(param)
        out = []
        with self._lock:
            for node in (list(wanted) if names else self.remote_nodes()):
                client = self._client(node)
                params = wanted.get(node)
                if params is None:
                    listed = self._call(client.list_parameters())
                    params = sorted(listed.result.names) if listed is not None else []
                values = self._call(client.get_parameters(params)) if params else None
                for param, value in zip(params, values.values if values is not None else []):
                    native = _native(value)
                    if native is not None:
                        out.append(foxglove.Parameter(f"{node}.{param}", value=native))
        return out

    def set_parameters(self, parameters: list[foxglove.Parameter]) -> list[foxglove.Parameter]:
        """Set ``/node.param`` through the node's set_parameters service; return the values now in force."""
        by_node: dict[str, list[ParameterMsg]] = {}
        for p in parameters:
            node, _, param = p.name.partition(".")
            value = p.get_value()
            if isinstance(value, bytes):  # byte arrays are not offered, so none come back
                continue
            by_node.setdefault(node, []).append(ParameterMsg(name=param, value=_ros_value(value)))
        with self._lock:
            for node, msgs in by_node.items():
                current = self._call(self._client(node).get_parameters([m.name for m in msgs]))
                if current is not None:  # keep the declared type: 1 for a double parameter is 1.0
                    for msg, old in zip(msgs, current.values):
                        _coerce(msg, old.type)
                results = self._call(self._client(node).set_parameters(msgs))
                for msg, result in zip(msgs, results.results if results is not None else []):
                    if not result.successful:
                        self.get_logger().warning(f"{node}: {msg.name} not set: {result.reason}")
        return self.get_parameters([p.name for p in parameters])

    def destroy_node(self) -> None:
        self.server.stop()
        for channel in self.channels.values():
            channel.close()
        super().destroy_node()


class _Listener(ServerListener):
    """The server's callbacks (foxglove.websocket.ServerListener protocol): channel subscriptions and
    parameters."""

    def __init__(self, bridge: FoxgloveBridge):
        self.bridge = bridge

    def on_subscribe(self, client, channel):
        self.bridge.watch(channel.topic, +1)

    def on_unsubscribe(self, client, channel):     # also called for each channel of a client that disconnects
        self.bridge.watch(channel.topic, -1)

    def on_client_advertise(self, client, channel):
        self.bridge.client_advertised(client.id, channel)

    def on_client_unadvertise(self, client, client_channel_id):
        self.bridge.client_unadvertised(client.id, client_channel_id)

    def on_message_data(self, client, client_channel_id, data):
        self.bridge.client_message(client.id, client_channel_id, data)

    def on_get_parameters(self, client, param_names, request_id=None):
        return self.bridge.get_parameters(list(param_names))

    def on_set_parameters(self, client, parameters, request_id=None):
        return self.bridge.set_parameters(list(parameters))


def _native(value):
    """A ROS parameter value as a Python value Foxglove takes (None for unset and byte arrays)."""
    if value.type in (ParameterType.PARAMETER_NOT_SET, ParameterType.PARAMETER_BYTE_ARRAY):
        return None
    native = parameter_value_to_python(value)
    return list(native) if isinstance(native, (tuple, list)) or hasattr(native, "tolist") else native


def _ros_value(value):
    return Parameter("_", value=value).to_parameter_msg().value


def _coerce(msg: ParameterMsg, declared: int) -> None:
    """An integer sent for a double parameter (JSON has one number type) becomes a double."""
    v = msg.value
    if declared == ParameterType.PARAMETER_DOUBLE and v.type == ParameterType.PARAMETER_INTEGER:
        msg.value = _ros_value(float(v.integer_value))
    elif declared == ParameterType.PARAMETER_DOUBLE_ARRAY and v.type == ParameterType.PARAMETER_INTEGER_ARRAY:
        msg.value = _ros_value([float(x) for x in v.integer_array_value])


def main(args=None) -> None:
    run_node(FoxgloveBridge, args)


if __name__ == "__main__":
    main()
