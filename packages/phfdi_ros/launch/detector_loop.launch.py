"""The pH loop (plant, valve, PI controllers) with the fault detector and the MCAP recorder, from the parameter
files the package installs (share/phfdi_ros/config/<node>.params.yaml: the default scenario, as `phfdi launch
--detector` runs it).

    ros2 launch phfdi_ros detector_loop.launch.py                     # records ./detector_loop.mcap
    ros2 launch phfdi_ros detector_loop.launch.py bag:=/tmp/run.mcap  # another bag (an existing one is not replaced)

The nodes keep DDS on this machine (they set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST when it is unset). The plant
owns simulated time and waits for every node of the graph (its graph_nodes parameter) before sample 0; when it has
run the scenario it exits and the launch shuts the other nodes down.

Not run on the machines this was written on (no launch / launch_ros there): docs/ros_graph.md, "Using the nodes in
your own workspace", says what was tested.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = "phfdi_ros"
#: node name (the key of its parameter file) -> executable (the console scripts of pyproject.toml)
NODES = {
    "controllers": "phfdi-controllers-node",
    "valve": "phfdi-valve-node",
    "plant": "phfdi-plant-node",
    "recorder": "phfdi-recorder-node",
    "detector": "phfdi-detector-node",  # the multichannel detector with the shipped physics reference
}


def generate_launch_description():
    config = os.path.join(get_package_share_directory(PACKAGE), "config")
    nodes = {}
    for name, executable in NODES.items():
        parameters = [os.path.join(config, f"{name}.params.yaml")]
        if name == "recorder":
            parameters.append({"path": LaunchConfiguration("bag")})
        nodes[name] = Node(package=PACKAGE, executable=executable, name=name, parameters=parameters,
                           output="screen", emulate_tty=True)
    return LaunchDescription([
        DeclareLaunchArgument("bag", default_value="detector_loop.mcap",
                              description="MCAP bag the recorder writes (.mcap; not replaced if it exists)"),
        *nodes.values(),
        # the plant exits when the scenario has run: stop the others (the recorder then finishes the bag)
        RegisterEventHandler(OnProcessExit(target_action=nodes["plant"],
                                           on_exit=[EmitEvent(event=Shutdown(reason="the plant finished"))])),
    ])
