"""Importing a node module has no side effects: the environment is left alone and nothing exits.

(Before: importing the node base set ROS_AUTOMATIC_DISCOVERY_RANGE and could end the process.) The check
that keeps DDS on this machine runs when a node starts (phfdi_base.ros.run.main), which test_env_cli covers.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

NODE_MODULES = ["ph_plant_sim.node", "valve_actuator.node", "pi_controllers.node", "wavelet_fdi.learned_node",
                "phfdi.ros.recorder", "phfdi.ros.player", "phfdi.ros.live_bridge"]

PROBE = """
import importlib, json, os, sys
before = dict(os.environ)
for name in sys.argv[1:]:
    importlib.import_module(name)
print(json.dumps({"changed": sorted(k for k in set(before) | set(os.environ) if before.get(k) != os.environ.get(k))}))
"""


@pytest.mark.parametrize("discovery", [None, "SUBNET"])
def test_importing_a_node_module_changes_nothing_and_does_not_exit(discovery):
    env = {k: v for k, v in os.environ.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    if discovery is not None:  # a value main() refuses: importing must still not exit
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = discovery
    out = subprocess.run([sys.executable, "-c", PROBE, *NODE_MODULES], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().splitlines()[-1] == '{"changed": []}', out.stdout
