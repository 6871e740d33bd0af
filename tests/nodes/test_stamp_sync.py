"""StampSync's lockstep data flow under foreign stamps, driven message by message (no ROS graph):
every real period runs exactly once, in order, whatever a foreign publisher interleaves."""
from types import SimpleNamespace

import pytest

from required import import_or_skip  # noqa: E402  (a missing rclpy fails in CI)
import_or_skip("rclpy")
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402

from cdpr_control.ros.sync import StampSync  # noqa: E402

PERIOD = 1_000_000
M = 2


class FakeNode:
    """What StampSync asks of a node: robot, period, parameters, subscriptions, clock, reports."""

    def __init__(self, sim_time: bool, clock_ns: int = 0):
        self.robot, self.dt, self.input_deadline = SimpleNamespace(m=M), PERIOD * 1e-9, 50
        self.sim_time, self.clock_ns = sim_time, clock_ns
        self.receivers, self.faults, self.stale = {}, [], []

    def has_parameter(self, name):
        return name == "use_sim_time"

    def get_parameter(self, name):
        return SimpleNamespace(value=self.sim_time)

    def create_subscription(self, msg_type, topic, callback, qos, **kwargs):
        self.receivers[topic] = callback
        return object()

    def create_timer(self, period, callback):
        return object()

    def get_clock(self):
        return SimpleNamespace(now=lambda: SimpleNamespace(nanoseconds=self.clock_ns))

    def input_fault(self, topic, reason):
        self.faults.append((topic, reason))

    def report_stale(self, ages, deadline, t):
        self.stale.append(dict(ages))


def state(t_ns: int, value: float = 1.0) -> JointState:
    sec, nanosec = divmod(t_ns, 1_000_000_000)
    return JointState(header=Header(stamp=Time(sec=sec, nanosec=nanosec)), position=[value] * M)


def make(sim_time=True):
    node = FakeNode(sim_time)
    runs = []
    sync = StampSync(node, {"a": (JointState, "a"), "b": (JointState, "b")}, "a",
                     lambda bucket, t: runs.append((t, bucket["a"].position[0], bucket["b"].position[0])))
    return node, sync, runs


def test_a_publisher_ahead_of_the_real_stream_leaves_every_real_period_complete():
    node, sync, runs = make()
    a, b = node.receivers["a"], node.receivers["b"]
    for k in range(1, 40):
        node.clock_ns = k * PERIOD
        a(state(k * PERIOD))
        if k % 5 == 0:                               # a foreign /b publisher 10 periods ahead
            b(state((k + 10) * PERIOD, value=-1.0))
        b(state(k * PERIOD))
    assert [t for t, _, _ in runs] == [k * PERIOD for k in range(1, 40)]     # once each, in order
    assert node.stale == []
    # the foreign message of a period that came before the real one completed that period (a
    # foreign publisher on a topic is an injection the stamps cannot tell from the real one); the
    # real one then comes after its period ran: dropped (refused as older, or taken as the stream
    # going on and pruned with its period), never run again
    foreign = {k for k in range(15, 40, 5)}
    assert {round(t / PERIOD) for t, _, b_value in runs if b_value == -1.0} == foreign
    older = [f for f in node.faults if "older" in f[1]]
    assert len(older) <= len(foreign), node.faults


@pytest.mark.parametrize("sim_time", [True, False])
def test_a_stream_of_one_far_stamp_is_refused_while_the_clock_runs(sim_time):
    node, sync, runs = make(sim_time)
    a, b = node.receivers["a"], node.receivers["b"]
    far = 5000 * 1_000_000_000
    for k in range(1, 200):
        node.clock_ns = k * PERIOD
        if k % 50 == 0:                             # 20 Hz of stamp.sec 5000 on both inputs
            a(state(far, value=-1.0))
            b(state(far, value=-1.0))
        a(state(k * PERIOD))
        b(state(k * PERIOD))
    ran = [t for t, _, _ in runs]
    if sim_time:       # against the simulated clock: every far stamp refused, every real period run
        assert ran == [k * PERIOD for k in range(1, 200)]
        assert all(v == 1.0 for _, v, _ in runs)
        assert len([f for f in node.faults if "ahead of the clock" in f[1]]) == 2 * 3
        assert sync.now < far
    else:              # no clock of its own: the restart rule, but the real stream still runs on
        assert ran[-1] == 199 * PERIOD


@pytest.mark.parametrize("lag", [60, 265])
def test_a_second_older_stream_on_an_input_never_takes_turns_with_the_real_one(lag):
    """A second publisher on an input whose stamps run ``lag`` periods behind the real stream (another
    graph on the ROS domain, a bag played into the graph): the restart rule took every second message
    of it for a restarted publisher, so the input's newest stamp jumped back and forth, the node
    reported it stale and fresh again every time its clock ticked (seen in a stress run: ages
    265-414 periods), and the older data ran periods. Against the simulated clock each such stamp is
    refused: every real period runs once, with real data, and nothing goes stale."""
    node, sync, runs = make()
    a, b = node.receivers["a"], node.receivers["b"]
    for k in range(lag + 1, lag + 200):
        node.clock_ns = k * PERIOD
        a(state(k * PERIOD))
        b(state(k * PERIOD))
        b(state((k - lag) * PERIOD, value=-1.0))     # the other stream, interleaved
        sync.advance(node.clock_ns)                  # the node's clock tick (StampSync._watch)
    assert [t for t, _, _ in runs] == [k * PERIOD for k in range(lag + 1, lag + 200)]
    assert all(b_value == 1.0 for _, _, b_value in runs)
    assert node.stale == []
    assert all("behind the clock" in reason for _, reason in node.faults) and len(node.faults) == 199


@pytest.mark.parametrize("mode", ["exact", "latest"])
def test_an_input_turns_stale_in_the_first_period_past_its_deadline(mode):
    """The deadlines are looked at only once an input could have passed its own (StampSync._calm_until):
    an input that stops is still reported stale in the first period more than input_deadline periods
    after its last stamp, each later period ticks on_stale, and its next message makes it fresh."""
    node = FakeNode(sim_time=False)
    ticks = []
    sync = StampSync(node, {"a": (JointState, "a"), "b": (JointState, "b")}, "a", lambda bucket, t: None,
                     mode=mode, on_stale=ticks.append)
    for k in range(1, 31):                  # both inputs, periods 1..30
        node.receivers["a"](state(k * PERIOD)), node.receivers["b"](state(k * PERIOD))
    for k in range(31, 81):                 # b stops: 50 periods within the deadline
        node.receivers["a"](state(k * PERIOD))
        assert sync.stale == () and node.stale == []
    node.receivers["a"](state(81 * PERIOD))     # 51 periods after b's last stamp
    assert sync.stale == ("b",) and node.stale == [{"b": 51.0}] and ticks == [81 * PERIOD]
    node.receivers["a"](state(82 * PERIOD))
    assert ticks == [81 * PERIOD, 82 * PERIOD]
    node.receivers["b"](state(82 * PERIOD))     # b is back
    assert sync.stale == () and node.stale[-1] == {}
    for k in range(83, 140):                # fresh again: stale again only past the new deadline
        node.receivers["a"](state(k * PERIOD))
    assert sync.stale == ("b",) and node.stale[-1] == {"b": 51.0}
