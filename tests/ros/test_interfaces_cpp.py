"""phfdi_interfaces built by a plain ``colcon build`` in a workspace (issue 36 item 10; C++ type support: issue 23
item 3), exactly as docs/ros_graph.md ("Using the nodes in your own workspace") says, and used from C++ and Python.

The command takes no CMake option: the package's CMakeLists finds the interpreter's Python and numpy include
directories itself where the ROS 2 wheels from PyPI point at ones that do not exist (/opt/python/...); before, the
build stopped at CMake's generate step unless given options found only in this test. What stands in for
``source /opt/ros/jazzy/setup.bash`` here, with the wheels and no ROS installation, is ``AMENT_PREFIX_PATH`` set to
the venv (the wheels have no setup script). The workspace builds both packages (phfdi_ros too); a C++ program fills
a ``phfdi_interfaces::msg::FaultAlarm`` and, after ``source install/setup.bash``, Python imports the workspace's
messages and round-trips a FaultAlarm with its ``statistic_name``. About 1 to 2 minutes (C++ generators).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

ROOT = Path(__file__).resolve().parents[2]
VENV = Path(sys.prefix)

CPP_USER = """
#include <phfdi_interfaces/msg/fault_alarm.hpp>
#include <iostream>
int main() {
  phfdi_interfaces::msg::FaultAlarm alarm;
  alarm.fault_class = "backlash";
  alarm.statistic_name = "ph.R.mean_down";
  alarm.state = phfdi_interfaces::msg::FaultAlarm::ALARM;
  std::cout << alarm.fault_class << " " << alarm.statistic_name << " " << int(alarm.state) << std::endl;
  return 0;
}
"""

PY_USER = """
from rclpy.serialization import deserialize_message, serialize_message
import phfdi_interfaces.msg as m
back = deserialize_message(serialize_message(m.FaultAlarm(statistic_name="ph.R.mean_down", state=2)), m.FaultAlarm)
print(back.statistic_name, back.state, m.__file__)
"""


def _run(cmd: list[str], **kw) -> None:
    done = subprocess.run(cmd, capture_output=True, text=True, **kw)
    assert done.returncode == 0, f"{' '.join(cmd[:3])} ...: {done.stdout[-2000:]}{done.stderr[-2000:]}"


def test_a_plain_colcon_build_of_the_workspace_builds_the_messages_for_cpp_and_python(tmp_path):
    for tool in ("cmake", "c++"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} not found")
    colcon = VENV / "bin" / "colcon"
    if not (VENV / "share" / "rosidl_default_generators").is_dir() or not colcon.exists():
        pytest.skip("the ROS 2 generators or colcon are not in this interpreter's prefix (run scripts/setup.sh)")
    ws = tmp_path / "phfdi_ws"
    (ws / "src").mkdir(parents=True)
    (ws / "src" / "phfdi").symlink_to(ROOT)
    env = {k: v for k, v in os.environ.items() if k != "_ROS_WHEELS_BOOTSTRAP_COMPLETE"}
    env["AMENT_PREFIX_PATH"] = str(VENV)  # what sourcing a ROS installation sets (the wheels have no setup script)
    _run([str(colcon), "build"], cwd=ws, env=env, timeout=540)  # the documented command: no options
    install = ws / "install" / "phfdi_interfaces"
    libs = {p.name for p in (install / "lib").glob("*.so")}
    assert {"libphfdi_interfaces__rosidl_typesupport_cpp.so",
            "libphfdi_interfaces__rosidl_typesupport_fastrtps_cpp.so"} <= libs, sorted(libs)
    assert (ws / "install" / "phfdi_ros" / "share" / "phfdi_ros" / "package.xml").exists()

    source = tmp_path / "use.cpp"
    source.write_text(CPP_USER)
    includes = [f"-I{install / 'include' / 'phfdi_interfaces'}"] + [f"-I{d}" for d in (VENV / "include").iterdir()]
    _run(["c++", "-std=c++17", *includes, str(source), "-o", str(tmp_path / "use")])
    out = subprocess.run([str(tmp_path / "use")], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["backlash", "ph.R.mean_down", "2"]

    script = tmp_path / "use.py"
    script.write_text(PY_USER)
    py = subprocess.run(["bash", "-c", f"source install/setup.bash && {sys.executable} {script}"], cwd=ws, env=env,
                        capture_output=True, text=True, timeout=120)
    assert py.returncode == 0, py.stderr
    name, state, module = py.stdout.split()
    assert (name, state) == ("ph.R.mean_down", "2")
    assert Path(module).is_relative_to(ws / "install" / "phfdi_interfaces"), module  # the workspace's messages
