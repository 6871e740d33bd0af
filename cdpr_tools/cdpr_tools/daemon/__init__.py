"""The graph daemon: one warm ROS node per ROS_DOMAIN_ID that answers the graph commands of ``cdpr``.

Without it every ``cdpr param get`` or ``cdpr topic echo --once`` discovers the graph from scratch
(1.4-6 s here). As ros2cli keeps a daemon for its graph queries (``ros2cli/daemon``, chosen in
``ros2cli/node/strategy.py``), the first such command starts ``server`` in a process of its own
and the next ones hand it their command line over a Unix domain socket (``client``): it runs the
same command code with its node, which has discovered the graph and keeps each node's parameter
clients, and sends back the output and exit status. ros2's daemon answers graph queries only (its
commands still call services themselves); this one runs whole commands, so the caller imports no
rclpy and never discovers anything.
"""
