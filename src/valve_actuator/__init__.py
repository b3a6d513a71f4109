"""Control valve with composable nonlinearity blocks (backlash, dead-zone,
friction, stiction, saturation, leakage, blocking). ROS-free; the node lives
in :mod:`valve_actuator.node`."""
