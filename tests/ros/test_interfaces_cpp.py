"""phfdi_interfaces with C++ type support (issue 23 item 3): the message package built as a ROS 2 workspace
builds it (every default generator, not the venv's Python-only set), and a C++ program uses FaultAlarm.

scripts/setup.sh builds the package with PHFDI_PYTHON_ONLY=ON into the venv; here it is built again without it,
into a temporary prefix, against the ROS 2 wheels' generators in the venv (about 30 s)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
VENV = Path(sys.prefix)

CPP_USER = """
#include <phfdi_interfaces/msg/fault_alarm.hpp>
#include <iostream>
int main() {
  phfdi_interfaces::msg::FaultAlarm alarm;
  alarm.fault_class = "backlash";
  alarm.state = phfdi_interfaces::msg::FaultAlarm::ALARM;
  std::cout << alarm.fault_class << " " << int(alarm.state) << std::endl;
  return 0;
}
"""


def _run(cmd: list[str], **kw) -> None:
    done = subprocess.run(cmd, capture_output=True, text=True, **kw)
    assert done.returncode == 0, f"{' '.join(cmd[:3])} ...: {done.stdout[-2000:]}{done.stderr[-2000:]}"


def test_the_messages_build_with_cpp_type_support_and_a_cpp_program_uses_them(tmp_path):
    for tool in ("cmake", "c++"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} not found")
    if not (VENV / "share" / "rosidl_default_generators").is_dir():
        pytest.skip("the ROS 2 generators are not in this interpreter's prefix (run scripts/setup.sh)")
    env = {**os.environ, "AMENT_PREFIX_PATH": str(VENV)}
    build, install = tmp_path / "build", tmp_path / "install"
    _run(["cmake", "-S", str(ROOT / "interfaces" / "phfdi_interfaces"), "-B", str(build),
          f"-DCMAKE_PREFIX_PATH={VENV}", f"-DCMAKE_INSTALL_PREFIX={install}", "-DBUILD_TESTING=OFF",
          f"-DPython3_EXECUTABLE={sys.executable}", "-DPython3_FIND_VIRTUALENV=ONLY",
          f"-DPHFDI_PYTHON_INCLUDE={sysconfig.get_paths()['include']}", f"-DPHFDI_NUMPY_INCLUDE={np.get_include()}"],
         env=env)
    _run(["cmake", "--build", str(build), "--parallel", "2"], env=env)
    _run(["cmake", "--install", str(build)], env=env)
    libs = {p.name for p in (install / "lib").glob("*.so")}
    assert {"libphfdi_interfaces__rosidl_typesupport_cpp.so",
            "libphfdi_interfaces__rosidl_typesupport_fastrtps_cpp.so"} <= libs, sorted(libs)
    source = tmp_path / "use.cpp"
    source.write_text(CPP_USER)
    includes = [f"-I{install / 'include' / 'phfdi_interfaces'}"] + [f"-I{d}" for d in (VENV / "include").iterdir()]
    _run(["c++", "-std=c++17", *includes, str(source), "-o", str(tmp_path / "use")])
    out = subprocess.run([str(tmp_path / "use")], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["backlash", "2"]
