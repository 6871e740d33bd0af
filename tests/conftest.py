"""Test-session environment: ROS 2 traffic stays on this machine, in a domain of its own."""
import os
import random

# Discovery only on localhost (no multicast leaves the machine), and a random domain so that
# concurrent test runs on one machine do not see each other's nodes.
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.Random(os.getpid()).randint(1, 100)))
