"""Recording a live graph with BagRecorder, playing bags back with BagPlayer and `cdpr bag play`."""
import threading
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Int32, String

from cdpr_test_nodes.graph import Collector, Spinner, wait_for
from cdpr_tools import cli
from cdpr_tools.bag import BagReader, BagWriter
from cdpr_tools.bag.player import BagPlayer
from cdpr_tools.bag.recorder import BagRecorder

T0 = 1000 * 10**9  # ns, bag start of the playback bags
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


@pytest.fixture
def spinners():
    made = []

    def make() -> Spinner:
        made.append(Spinner())
        return made[-1]

    yield make
    for s in reversed(made):
        s.close()


def test_recorder_writes_every_topic_with_types_counts_and_qos(tmp_path, spinners):
    graph, rec = spinners(), spinners()
    node = graph.add(Collector, topics={})
    chatter = node.create_publisher(String, "chatter", 10)
    joints = node.create_publisher(JointState, "joint_states", 10)
    status = node.create_publisher(String, "status", LATCHED)
    status.publish(String(data="latched"))  # before the recorder exists: transient local delivers it
    recorder = rec.add(BagRecorder, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "live")), Parameter("exclude", value="/rosout|/parameter_events")])
    wait_for(lambda: {"/chatter", "/joint_states", "/status"} <= set(recorder.recorded_topics), what="subscriptions")
    wait_for(lambda: chatter.get_subscription_count() and joints.get_subscription_count(), what="matching")
    for i in range(50):
        chatter.publish(String(data=str(i)))
        joints.publish(JointState(name=["a", "b"], position=[float(i), 2.0 * i]))
        time.sleep(0.002)
    wait_for(lambda: recorder.writer.message_count >= 101, what="all messages recorded")
    rec.close()  # destroys the recorder: closes the bag

    bag = BagReader(tmp_path / "live")
    assert {t: (i.type, i.message_count) for t, i in bag.topics.items()} == {
        "/chatter": ("std_msgs/msg/String", 50), "/joint_states": ("sensor_msgs/msg/JointState", 50),
        "/status": ("std_msgs/msg/String", 1)}
    assert bag.topics["/status"].offered_qos_profiles[0]["durability"] == "transient_local"
    assert bag.topics["/chatter"].type_description_hash.startswith("RIHS01_")
    assert [m.msg.data for m in bag.messages(["/chatter"])] == [str(i) for i in range(50)]
    times = [m.log_time_ns for m in bag.messages()]
    assert times == sorted(times)
    store = get_typestore(Stores.EMPTY)  # and the other readers agree
    with RosbagsReader(tmp_path / "live") as reader:
        for c in reader.connections:
            store.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        decoded = [store.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert len(decoded) == 101


def test_recorder_log_time_is_sim_time_with_clock(tmp_path, spinners):
    graph, rec = spinners(), spinners()
    node = graph.add(Collector, topics={})
    clock = node.create_publisher(Clock, "/clock", 10)
    data = node.create_publisher(Int32, "data", 10)
    recorder = rec.add(BagRecorder, parameter_overrides=[
        Parameter("output", value=str(tmp_path / "sim")), Parameter("topics", value=["/data"]),
        Parameter("use_sim_time", value=True)])
    wait_for(lambda: "/data" in recorder.recorded_topics and data.get_subscription_count(), what="recorder")

    def clock_is(sec: int) -> bool:
        clock.publish(Clock(clock=Time(sec=sec)))
        time.sleep(0.01)
        return recorder.get_clock().now().nanoseconds == sec * 10**9

    for sec in (100, 101):
        wait_for(lambda: clock_is(sec), what=f"recorder clock at {sec} s")
        data.publish(Int32(data=sec))
        wait_for(lambda: recorder.writer.message_count >= sec - 99, what="message recorded")
    rec.close()
    bag = BagReader(tmp_path / "sim")
    assert list(bag.topics) == ["/data"]
    assert [(m.log_time_ns, m.msg.data) for m in bag.messages()] == [(100 * 10**9, 100), (101 * 10**9, 101)]


def write_playback_bag(path) -> dict:
    """1 s of data: /p1 every 50 ms (String), /p2 every 100 ms (Int32), /latched once."""
    with BagWriter(path) as bag:
        bag.write("/latched", None, String(data="config"), T0, qos=LATCHED)
        for i in range(20):
            bag.write("/p1", None, String(data=f"m{i}"), T0 + i * 50_000_000, qos=QoSProfile(depth=10))
            if i % 2 == 0:
                bag.write("/p2", None, Int32(data=i), T0 + i * 50_000_000)
    return {"/p1": [f"m{i}" for i in range(20)], "/p2": list(range(0, 20, 2))}


def check_never_early(start: float, arrivals: list[float], offsets_s: list[float]) -> None:
    """No message arrives before its schedule: arrival_i >= publish_i >= wall0 + offset_i >= start +
    offset_i, with ``start`` the monotonic time taken before play began. Exact whatever the load of
    the machine (a busy machine only makes a message later); the schedule itself is checked
    deterministically, on a simulated clock, by test_player_publishes_on_its_schedule."""
    assert len(arrivals) == len(offsets_s)
    for arrived, offset in zip(arrivals, offsets_s):
        assert arrived >= start + offset, (arrived - start, offset)


class SimulatedClock:
    """time.monotonic() and threading.Event().wait(timeout) on a clock that advances only when the
    player waits: the player's schedule without the machine's scheduling in it."""

    def __init__(self):
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def wait(self, timeout: float) -> bool:
        self.now += timeout
        return False

    def is_set(self) -> bool:
        return False


class PublishLog:
    def __init__(self, topic: str, clock: SimulatedClock, log: list):
        self.topic, self.clock, self.log = topic, clock, log

    def publish(self, msg) -> None:
        self.log.append((self.clock.now, self.topic, msg))


def test_player_publishes_on_its_schedule(tmp_path, spinners, monkeypatch):
    """Every message at wall0 + (t_log - t_start) / rate exactly, /clock ticks at its rate with the
    bag time, on the simulated clock (no dependence on how busy the machine is)."""
    import types

    from cdpr_tools.bag import player as player_module

    write_playback_bag(tmp_path / "play")
    clock, log = SimulatedClock(), []
    monkeypatch.setattr(player_module, "time", types.SimpleNamespace(monotonic=clock.monotonic))
    node = spinners().add(Collector, topics={})
    player = BagPlayer(node, BagReader(tmp_path / "play"), rate=2.0, clock_hz=40.0)
    player.publishers = {t: PublishLog(t, clock, log) for t in player.publishers}
    ticks = []
    player._publish_clock = lambda t_ns: ticks.append((clock.now, t_ns))
    start = clock.now
    assert player.play(stop=clock) == 31
    from rclpy.serialization import deserialize_message   # the player publishes the recorded bytes

    p1 = [(t - start, deserialize_message(m, String).data) for t, topic, m in log if topic == "/p1"]
    assert [d for _, d in p1] == [f"m{i}" for i in range(20)]
    np.testing.assert_allclose([t for t, _ in p1], [i * 0.05 / 2.0 for i in range(20)], rtol=0, atol=1e-9)
    assert [t - start for t, topic, _ in log if topic == "/latched"] == [0.0]
    # /clock every 1/40 s of wall time, carrying the bag time (twice the wall time at rate 2)
    walls = np.array([t - start for t, _ in ticks])
    np.testing.assert_allclose(np.diff(walls), 1 / 40.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose([t_ns - T0 for _, t_ns in ticks], walls * 2.0 * 1e9, rtol=0, atol=2.0)


def test_player_republishes_types_qos_and_timing(tmp_path, spinners):
    expected = write_playback_bag(tmp_path / "play")
    listen, play = spinners(), spinners()
    collector = listen.add(Collector, topics={"/p1": String, "/p2": Int32})
    late = listen.add(Collector, topics={"/latched": String}, qos=LATCHED)
    player_node = play.add(Collector, topics={})
    player = BagPlayer(player_node, BagReader(tmp_path / "play"), rate=2.0)
    assert player.publishers["/latched"].qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert player.wait_for_subscribers(15.0)
    start = time.monotonic()
    assert player.play() == 31
    wait_for(lambda: collector.count("/p1") == 20 and collector.count("/p2") == 10, what="every message")
    assert [m.data for m in collector.messages("/p1")] == expected["/p1"]
    assert [m.data for m in collector.messages("/p2")] == expected["/p2"]
    wait_for(lambda: late.count("/latched") == 1, what="latched message")
    arrivals = [t for t, _ in collector.received["/p1"]]
    check_never_early(start, arrivals, [i * 0.05 / 2.0 for i in range(20)])


def test_player_start_offset_and_topic_filter(tmp_path, spinners):
    write_playback_bag(tmp_path / "play")
    listen, play = spinners(), spinners()
    collector = listen.add(Collector, topics={"/p1": String, "/p2": Int32})
    player = BagPlayer(play.add(Collector, topics={}), BagReader(tmp_path / "play"), rate=4.0,
                       topics=["/p1"], start_offset=0.5)
    assert list(player.publishers) == ["/p1"]
    assert player.wait_for_subscribers(15.0)
    assert player.play() == 10
    wait_for(lambda: collector.count("/p1") == 10, what="second half of /p1")
    assert [m.data for m in collector.messages("/p1")] == [f"m{i}" for i in range(10, 20)]
    assert collector.count("/p2") == 0
    with pytest.raises(ValueError, match="topics: /latched, /p1, /p2"):
        BagPlayer(play.nodes[0], BagReader(tmp_path / "play"), topics=["/nope"])


def test_cdpr_bag_play_with_clock(tmp_path, spinners, capfd):
    expected = write_playback_bag(tmp_path / "play")
    listen = spinners()
    collector = listen.add(Collector, topics={"/p1": String, "/p2": Int32, "/clock": Clock})
    start = time.monotonic()
    rc = cli.main(["bag", "play", str(tmp_path / "play"), "--clock", "50", "--rate", "2",
                   "--topics", "/p1", "/p2", "--wait-for-subscribers", "15"])
    assert rc == 0
    assert "published 30 messages" in capfd.readouterr().out
    wait_for(lambda: collector.count("/p1") == 20 and collector.count("/p2") == 10, what="every message")
    assert [m.data for m in collector.messages("/p2")] == expected["/p2"]
    check_never_early(start, [t for t, _ in collector.received["/p1"]], [i * 0.025 for i in range(20)])
    clock = [m.clock.sec * 10**9 + m.clock.nanosec for m in collector.messages("/clock")]
    assert len(clock) >= 5  # 0.475 s of playback at 50 Hz, some lost to discovery at most
    assert clock == sorted(clock)
    assert T0 <= clock[0] and clock[-1] <= T0 + 950_000_000
    assert clock[-1] - clock[0] >= 0.5 * 950_000_000 * 0.5  # /clock runs at bag speed, 2x wall


def test_cdpr_bag_record_and_info(tmp_path, spinners, capfd):
    graph = spinners()
    node = graph.add(Collector, topics={})
    pub = node.create_publisher(String, "rec_me", 10)
    stop = threading.Event()

    def publish():
        i = 0
        while not stop.is_set():
            pub.publish(String(data=str(i)))
            i += 1
            time.sleep(0.01)

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        rc = cli.main(["bag", "record", "/rec_me", "-o", str(tmp_path / "cli"), "--stop-after", "3"])
    finally:
        stop.set()
        thread.join()
    assert rc == 0
    out = capfd.readouterr().out
    assert "recording to" in out and "messages on 1 topics" in out
    bag = BagReader(tmp_path / "cli")
    assert list(bag.topics) == ["/rec_me"] and bag.topics["/rec_me"].message_count > 0
    numbers = [int(m.msg.data) for m in bag.messages()]
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))  # nothing lost in between
    assert cli.main(["bag", "info", str(tmp_path / "cli")]) == 0
    info = capfd.readouterr().out
    assert "Storage id:        mcap" in info
    assert f"Topic: /rec_me | Type: std_msgs/msg/String | Count: {len(numbers)} |" in info


def test_play_remaps_topics(tmp_path, spinners, capfd):
    """--remap FROM:=TO publishes the bag's FROM on TO (as ros2 bag play --remap); a FROM the bag
    does not have is refused naming the bag's topics."""
    expected = write_playback_bag(tmp_path / "play")
    collector = spinners().add(Collector, topics={"/replay/p1": String, "/p1": String})
    rc = cli.main(["bag", "play", str(tmp_path / "play"), "--rate", "4", "--topics", "/p1",
                   "--remap", "p1:=/replay/p1", "--wait-for-subscribers", "15"])
    assert rc == 0
    wait_for(lambda: collector.count("/replay/p1") == 20, what="the remapped messages")
    assert [m.data for m in collector.messages("/replay/p1")] == expected["/p1"]
    assert collector.count("/p1") == 0
    capfd.readouterr()
    assert cli.main(["bag", "play", str(tmp_path / "play"), "--remap", "/nope:=/x"]) != 0
    assert "/nope" in capfd.readouterr().err
    with pytest.raises(SystemExit):
        cli.main(["bag", "play", str(tmp_path / "play"), "--remap", "p1=/x"])


def test_player_at_any_rate_stops_when_asked_and_refuses_what_it_cannot_time(tmp_path, spinners):
    """At rate 1e-300 the second message is 1e298 s away: the player waits in slices, so a stop
    (Ctrl-C) ends it (issue 28: a single wait that long overflowed). A /clock rate whose period
    vanishes beside the monotonic clock (1e300 Hz never advanced: play spun for ever, deaf to
    SIGTERM) and an offset beyond the bag's nanosecond times are refused."""
    write_playback_bag(tmp_path / "play")
    node = spinners().add(Collector, topics={})
    player = BagPlayer(node, BagReader(tmp_path / "play"), rate=1e-300)
    stop, played = threading.Event(), []
    thread = threading.Thread(target=lambda: played.append(player.play(stop)), daemon=True)
    thread.start()
    wait_for(lambda: player.published >= 1, what="the messages at the bag's start")
    stop.set()
    thread.join(60.0)
    assert not thread.is_alive() and played == [player.published] and 1 <= player.published < 31
    for kwargs, what in (({"clock_hz": 1e300}, "clock rate"), ({"clock_hz": -1.0}, "clock rate"),
                         ({"start_offset": 1e300}, "start offset"), ({"rate": float("nan")}, "rate")):
        with pytest.raises(ValueError, match=what):
            BagPlayer(node, BagReader(tmp_path / "play"), **kwargs)
