"""Simulated pH neutralization plant: chemistry by reaction invariants, a CSTR
with level dynamics, and sensor blocks. ROS-free; the node lives in
:mod:`ph_plant_sim.node`."""
