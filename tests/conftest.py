"""Shared fixtures: where ../shared/data is, and marks."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the real measured data; override with PHFDI_SHARED_DATA
SHARED_DATA = Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data folder not found at {SHARED_DATA} (set PHFDI_SHARED_DATA)")
    return SHARED_DATA


GRAPH_TEST_DIRS = {"ros", "detector_node"}
# every graph a test starts reserves a domain of its own; an exported ROS_DOMAIN_ID (which the commands use,
# as a ROS user expects) would put them all on one
os.environ.pop("ROS_DOMAIN_ID", None)


@pytest.fixture
def run_cli(capsys):
    """Run `phfdi ...` in process: (exit status, stdout, stderr)."""
    from phfdi.cli import main

    def run(*argv: object):
        status = main([str(a) for a in argv])
        out = capsys.readouterr()
        return status, out.out, out.err

    return run


@pytest.hookimpl(tryfirst=True)  # before xdist's hook reads the marks (this conftest registers before it)
def pytest_collection_modifyitems(config, items):
    """Tests that start ROS 2 graphs run one after another on one xdist worker (``--dist loadgroup``), the rest
    beside them: two graphs at once on 2 cores slow each other's lock step, and Fast DDS's per-participant
    shared-memory ports (7000 + i) are shared across ROS domains, so one test's killed node would show up in
    the other's shared-memory check."""
    for item in items:
        if item.get_closest_marker("ros") or Path(str(item.fspath)).parent.name in GRAPH_TEST_DIRS:
            item.add_marker(pytest.mark.xdist_group("ros_graph"))


def pytest_runtest_setup(item):
    """Fail a grouped test when --dist loadgroup does not group (a pytest/xdist pair that loses the group suffix,
    pytest-dev/pytest-xdist#1386): graph tests would run two at once and fail by chance, not by a bug."""
    grouping = getattr(item.config.option, "loadgroup", False)  # the option exists only under xdist
    if grouping and item.get_closest_marker("xdist_group") and "@" not in item.nodeid:
        pytest.fail(f"--dist loadgroup is not grouping with pytest {pytest.__version__}: install the pytest "
                    "the project pins (bash scripts/setup.sh)", pytrace=False)
