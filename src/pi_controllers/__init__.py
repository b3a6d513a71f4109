"""PI controllers with anti-windup and setpoint profiles. ROS-free; the node
lives in :mod:`pi_controllers.node`."""
