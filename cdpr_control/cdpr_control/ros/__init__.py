"""The ROS 2 node layer: the node base, parameters, QoS, input synchronisation, timing, the runner, message conversions and intra-process delivery."""
