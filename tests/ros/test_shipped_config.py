"""config/<node>.params.yaml equal what the launcher writes for the default scenario; the ROS package's files are
well formed (the launch file compiles; it cannot run here: no launch_ros on PyPI)."""

from __future__ import annotations

import py_compile
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import yaml

from phfdi.ros.shipped_config import PER_LAUNCH, RECORDER_SHIPPED, launcher_params, shipped_files, shipped_graph
from phfdi_base import topics as T

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "packages" / "phfdi_ros"


def test_config_holds_exactly_what_the_launcher_writes():
    on_disk = {p.name: p.read_text() for p in (REPO / "config").glob("*.params.yaml")}
    assert on_disk == shipped_files(), "regenerate: python -m phfdi.ros.shipped_config --write config"
    assert sorted(on_disk) == sorted(f"{n}.params.yaml" for n in (T.CONTROLLERS, T.VALVE, T.PLANT, T.RECORDER,
                                                                   T.DETECTOR))


def test_shipped_files_differ_from_the_launchers_only_in_the_per_launch_values():
    written = launcher_params(shipped_graph())
    for name, text in shipped_files().items():
        node = name.removesuffix(".params.yaml")
        shipped = yaml.safe_load(text)[node]["ros__parameters"]
        launched = written[node]
        assert set(launched) - set(shipped) == set(PER_LAUNCH)
        assert Path(launched["part"]).name.startswith("part")  # a temporary file of that launch
        changed = {k for k in shipped if shipped[k] != launched[k]}
        assert changed == (set(RECORDER_SHIPPED) if node == T.RECORDER else set()), node
    assert written[T.RECORDER]["path"].endswith("/detector_loop.mcap")


def test_check_fails_on_a_stale_file(tmp_path):
    cmd = [sys.executable, "-m", "phfdi.ros.shipped_config"]
    assert subprocess.run([*cmd, "--write", str(tmp_path)], capture_output=True, timeout=120).returncode == 0
    assert subprocess.run([*cmd, "--check", str(tmp_path)], capture_output=True, timeout=120).returncode == 0
    stale = tmp_path / "plant.params.yaml"
    stale.write_text(stale.read_text().replace("pace: 0.0", "pace: 2.0"))
    out = subprocess.run([*cmd, "--check", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 1 and "plant.params.yaml differs" in out.stderr


def test_launch_file_compiles(tmp_path):
    py_compile.compile(str(PACKAGE / "launch" / "detector_loop.launch.py"), cfile=str(tmp_path / "launch.pyc"),
                       doraise=True)


def test_package_xml_is_format_3_ament_python_with_the_runtime_dependencies():
    root = ET.parse(PACKAGE / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == "phfdi_ros"
    assert root.find("export").findtext("build_type") == "ament_python"
    depends = {e.text for e in root.findall("exec_depend")}
    assert {"rclpy", "rcl_interfaces", "diagnostic_msgs", "rosgraph_msgs", "phfdi_interfaces", "launch_ros"} <= depends
    assert (PACKAGE / "resource" / "phfdi_ros").is_file()
