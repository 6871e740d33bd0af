"""QoS profiles of the cdpr graph, chosen once for every node.

- CONTROL: the 1 kHz loop topics (winch state and command, forces, poses, set-points, controller
  states). Reliable so that the lockstep simulation never loses a cycle (on one machine reliability
  costs no latency); keep-last 10 so a slow subscriber sees the newest data, not a backlog.
- STATUS: low-rate state a late joiner needs at once (program status, force limits): reliable,
  transient-local, keep-last 1.
- DIAGNOSTICS: /diagnostics as ROS tools expect it: reliable, keep-last 10.
"""
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

CONTROL = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
STATUS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
DIAGNOSTICS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
