"""The ROS 2 node graph's shared pieces.

``topics`` (the topic table) and ``env`` (environment, domain ids) import no
rclpy; ``node`` (the base of every graph node), ``recorder`` and the node
modules of the four packages do. ``launcher`` starts the graph as processes.
"""
