"""The ROS edge's base: what every node of the graph shares (importing this package does not import rclpy).

:mod:`phfdi_base.ros.env` (no rclpy): LOCALHOST discovery, graph environments, ROS domain leases.
:mod:`phfdi_base.ros.graph_node`: :class:`GraphNode`, built from :mod:`~phfdi_base.ros.params`,
:mod:`~phfdi_base.ros.barrier` and run as a process by :func:`phfdi_base.ros.run.main`.
"""
