"""cdpr_sim: the winch and platform simulator (pybullet); the ROS node lives in cdpr_sim.nodes."""
