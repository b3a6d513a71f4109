"""packages/phfdi_ros built by colcon (from PyPI) into a temporary workspace whose src/ links to this repository,
and the installed executables run with the installed parameter files: the loop with the detector and the
recorder, lock-step, equal to `phfdi launch` of the same graph. The default scenario is healthy (no alarm to
compare), so both runs add the same fault (``fault:=backlash`` on every node, as `phfdi launch --fault backlash`).

What this cannot run here: launch/detector_loop.launch.py under `ros2 launch` (launch and launch_ros are not on
PyPI; tests/ros/test_shipped_config.py only compiles it). This test ignores phfdi_interfaces (built into the venv
by scripts/build_interfaces.sh; colcon takes it from there) to stay fast; tests/ros/test_interfaces_cpp.py runs
the documented plain `colcon build` of both packages.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import yaml

from phfdi import bagio
from phfdi.ros.launcher import OBSERVER, Launcher, NodeSpec, loop_graph
from phfdi.ros.shipped_config import shipped_files, shipped_graph
from phfdi_base import topics as T
from wavelet_fdi import alarm_messages

from .conftest import processes_with

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.timeout(400)]

REPO = Path(__file__).resolve().parents[2]
PACKAGE = "phfdi_ros"
LAUNCH_FILE = REPO / "packages" / PACKAGE / "launch" / "detector_loop.launch.py"
FAULT = "backlash"  # both runs: the shipped files describe a healthy loop
SCRIPTS = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]


def launch_file_nodes() -> dict[str, str]:
    """The launch file's NODES (node name -> executable), read without importing launch_ros."""
    tree = ast.parse(LAUNCH_FILE.read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "NODES":
            return ast.literal_eval(node.value)
    raise AssertionError("no NODES in the launch file")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """`colcon build` of a workspace whose src/ links to the repository; phfdi_interfaces from the venv."""
    ws = tmp_path_factory.mktemp("colcon_ws")
    (ws / "src").mkdir()
    (ws / "src" / "phfdi").symlink_to(REPO)
    colcon = Path(sys.executable).parent / "colcon"
    assert colcon.exists(), "colcon is missing: bash scripts/setup.sh installs it (test extra)"
    listed = subprocess.run([str(colcon), "list", "--names-only"], cwd=ws, capture_output=True, text=True, timeout=60)
    env = {**os.environ, "AMENT_PREFIX_PATH": sys.prefix}
    t0 = time.monotonic()
    build = subprocess.run([str(colcon), "build", "--packages-ignore", "phfdi_interfaces"], cwd=ws, env=env,
                           capture_output=True, text=True, timeout=300)
    return {"ws": ws, "listed": listed, "build": build, "build_s": time.monotonic() - t0,
            "prefix": ws / "install" / PACKAGE}


def test_colcon_finds_both_packages_and_builds_the_nodes_package(workspace):
    assert workspace["listed"].stdout.split() == ["phfdi_interfaces", PACKAGE], workspace["listed"].stderr
    build = workspace["build"]
    assert build.returncode == 0, build.stdout + build.stderr
    assert "1 package finished" in build.stdout
    print(f"colcon build: {workspace['build_s']:.1f} s")  # measured 2.5 to 4 s here


def test_install_has_the_executables_config_launch_file_and_index_marker(workspace):
    assert workspace["build"].returncode == 0, workspace["build"].stderr
    prefix = workspace["prefix"]
    executables = sorted(p.name for p in (prefix / "lib" / PACKAGE).iterdir())
    assert executables == sorted(SCRIPTS)  # the same console scripts as pip install -e .
    assert all(os.access(prefix / "lib" / PACKAGE / e, os.X_OK) for e in executables)
    assert set(launch_file_nodes().values()) <= set(SCRIPTS)
    share = prefix / "share" / PACKAGE
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).is_file()
    assert (share / "package.xml").read_text() == (REPO / "packages" / PACKAGE / "package.xml").read_text()
    assert (share / "launch" / LAUNCH_FILE.name).read_text() == LAUNCH_FILE.read_text()
    installed = {p.name: p.read_text() for p in (share / "config").iterdir()}
    assert installed == shipped_files()
    assert sorted(n.removesuffix(".params.yaml") for n in installed) == sorted(launch_file_nodes())


#: what `source install/setup.bash` sets that the nodes' processes use
SOURCED = ("PYTHONPATH", "AMENT_PREFIX_PATH", "PATH", "COLCON_PREFIX_PATH")


def sourced_env(ws: Path) -> dict[str, str]:
    """This environment after `source install/setup.bash` of the workspace (the PYTHONPATH of this test process,
    the repository's src/, is dropped first: only the install is on the path)."""
    base = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run(["bash", "-c", "source install/setup.bash && env -0"], cwd=ws, env=base,
                         capture_output=True, timeout=60, check=True).stdout.decode()
    env = dict(item.split("=", 1) for item in out.split("\0") if "=" in item)
    return {**base, **{k: env[k] for k in SOURCED if k in env}}


def test_installed_code_is_the_installed_copy(workspace):
    """The executables import the workspace's install, not the repository's src/ or another editable install."""
    assert workspace["build"].returncode == 0, workspace["build"].stderr
    prefix = workspace["prefix"]
    code = ("import importlib.metadata as m, ph_plant_sim.node, phfdi.ros.recorder, wavelet_fdi.learned_node as d;"
            "print(ph_plant_sim.node.__file__); print(phfdi.ros.recorder.__file__); print(d.__file__);"
            "print(sorted(e.value for e in m.entry_points(group='phfdi.node_parts'))[0])")
    out = subprocess.run([sys.executable, "-c", code], env=sourced_env(workspace["ws"]), capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    *files, resolver = out.stdout.split()
    assert all(f.startswith(str(prefix)) for f in files), files
    assert resolver == "phfdi.ros.parts:make_part"


class InstalledLauncher(Launcher):
    """The launcher's process handling (start order, watchdog, stop order, bag finishing), but each node started
    as the installed executable with the installed parameter file, as a user's launch file does."""

    def __init__(self, nodes, prefix: Path, bag: Path, **kw) -> None:
        super().__init__(nodes, **kw)
        self.prefix, self.bag = prefix, bag

    def _write_params(self, spec: NodeSpec) -> list[str]:
        cmd = [str(self.prefix / "lib" / PACKAGE / launch_file_nodes()[spec.name]), "--ros-args", "--params-file",
               str(self.prefix / "share" / PACKAGE / "config" / f"{spec.name}.params.yaml")]
        cmd += ["-p", f"fault:={FAULT}"]
        return cmd + (["-p", f"path:={self.bag}"] if spec.name == T.RECORDER else [])


def installed_graph(prefix: Path, bag: Path) -> list[NodeSpec]:
    """The graph as the installed files describe it (no part file: the nodes resolve the scenario themselves)."""
    specs = []
    for spec in shipped_graph():
        doc = yaml.safe_load((prefix / "share" / PACKAGE / "config" / f"{spec.name}.params.yaml").read_text())
        params = doc[spec.name]["ros__parameters"]
        if spec.name == T.RECORDER:
            params["path"] = str(bag)
        specs.append(NodeSpec(spec.name, spec.module, params, spec.role))
    assert [s.name for s in specs if s.role == OBSERVER] == [T.RECORDER, T.DETECTOR]
    return specs


def test_installed_executables_run_the_loop_like_phfdi_launch(workspace, tmp_path, monkeypatch):
    assert workspace["build"].returncode == 0, workspace["build"].stderr
    prefix = workspace["prefix"]
    bags = {"installed": tmp_path / "installed.mcap", "launch": tmp_path / "launch.mcap"}
    results = {}
    # phfdi launch --fault backlash --detector --record launch.mcap (python -m <module> from this checkout,
    # parameters and part file written per launch)
    nodes = loop_graph(fault=FAULT, record=bags["launch"], detector={})
    results["launch"] = Launcher(nodes, log_dir=tmp_path / "launch_logs").run()
    # the installed executables with the installed parameter files
    env = sourced_env(workspace["ws"])
    for key in SOURCED:
        monkeypatch.setenv(key, env[key])
    results["installed"] = InstalledLauncher(installed_graph(prefix, bags["installed"]), prefix, bags["installed"],
                                             log_dir=tmp_path / "installed_logs").run()
    monkeypatch.undo()
    for how, r in results.items():
        assert r.status == 0 and r.failure is None, (how, r.failure, r.notes)
        assert r.samples_done == r.samples == 10001, how
        print(f"{how}: connected in {r.connect_s:.1f} s, ran in {r.run_wall_s:.1f} s")
    assert processes_with(str(tmp_path)) == []
    counts = {how: {t["topic"]: t["count"] for t in bagio.bag_info(bags[how])["topics"]} for how in bags}
    for topic in T.RECORDED:
        if topic.per_sample:
            assert counts["installed"][topic.name] == counts["launch"][topic.name] == 10001, topic.name
    # the detector ran in both and published its state (every change and every 60 s of simulated time)
    assert counts["installed"][T.FAULT_ALARM.name] > 100 and counts["launch"][T.FAULT_ALARM.name] > 100
    got, want = bagio.load_run(bags["installed"]), bagio.load_run(bags["launch"])
    assert got.names == want.names
    for name in want.names:
        same = (got[name] == want[name]) | (np.isnan(got[name]) & np.isnan(want[name]))
        assert same.all(), f"{name}: max difference {np.nanmax(np.abs(got[name] - want[name]))}"
    # the recorder computed the run metadata the launcher passes (but the bag's own path)
    assert {k: v for k, v in got.metadata.items() if k != "source"} == \
           {k: v for k, v in want.metadata.items() if k != "source"}
    alarms = {how: alarm_messages.per_alarm(bagio.fault_alarms(bags[how])) for how in bags}
    assert [(a["detection_time"], a["fault_class"]) for a in alarms["installed"]] == \
           [(a["detection_time"], a["fault_class"]) for a in alarms["launch"]]
    assert alarms["launch"] and alarms["launch"][-1]["fault_class"] == FAULT
    print(f"alarms (installed, launch): {len(alarms['installed'])}, {len(alarms['launch'])}; /fault_alarm messages: "
          f"{counts['installed'][T.FAULT_ALARM.name]}, {counts['launch'][T.FAULT_ALARM.name]}")


def test_symlink_install_links_to_the_sources_and_leaves_them_alone(tmp_path):
    """`colcon build --symlink-install` over a workspace holding a real copy of the repository: the copy is intact
    afterwards (a package_dir with '..' would have made colcon replace it: see packages/phfdi_ros/setup.py) and
    the sourced workspace imports the copy's files."""
    ws = tmp_path / "ws"
    clone = ws / "src" / "phfdi"
    clone.mkdir(parents=True)
    for item in ("pyproject.toml", "src", "config", "packages", "interfaces"):
        src, dst = REPO / item, clone / item
        if src.is_dir():
            shutil.copytree(src, dst, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, dst)
    before = sorted(str(p.relative_to(clone)) for p in clone.rglob("*"))
    colcon = Path(sys.executable).parent / "colcon"
    build = subprocess.run([str(colcon), "build", "--symlink-install", "--packages-ignore", "phfdi_interfaces"],
                           cwd=ws, env={**os.environ, "AMENT_PREFIX_PATH": sys.prefix}, capture_output=True, text=True,
                           timeout=300)
    assert build.returncode == 0, build.stdout + build.stderr
    assert clone.is_dir() and not clone.is_symlink()
    assert sorted(str(p.relative_to(clone)) for p in clone.rglob("*")) == before
    out = subprocess.run([sys.executable, "-c", "import wavelet_fdi.learned_node as m, os; "
                                            "print(os.path.realpath(m.__file__))"],
                         env=sourced_env(ws), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str((clone / "src" / "wavelet_fdi" / "learned_node.py").resolve())
    assert (ws / "install" / PACKAGE / "lib" / PACKAGE / "phfdi-detector-node").exists()
