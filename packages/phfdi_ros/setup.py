"""ament_python package phfdi_ros: the graph's nodes from the repository's src/, for `colcon build`.

Why a package of its own here and not a setup.py at the repository root: the root keeps its pyproject.toml for
`pip install -e .` (scripts/setup.sh) untouched, and colcon, crawling a workspace, finds this package.xml (and
interfaces/phfdi_interfaces) but no package at the root. The code is not copied: src and config here are
symlinks to the repository's (git stores them), and the console scripts, the ``phfdi.node_parts`` entry point
and the package data come from the repository's pyproject.toml, so the executables are the same entry points as
`pip install` makes.

Why symlinks and not ``package_dir={"": "../../src"}``: colcon's --symlink-install mirrors package_dir and the
data files' paths into build/<package>/, so a path with ``..`` leaves the build folder. Tried here: it replaced
the workspace's src/phfdi link with a link to itself. Read, not tried: over a real clone the same code
(colcon_core/task/python/build.py, _symlinks_in_build) calls shutil.rmtree on the clone. Every path below stays
inside this folder.
"""

import tomllib
from glob import glob
from pathlib import Path

from setuptools import find_namespace_packages, setup

NAME = "phfdi_ros"
# the repository (read only): resolved from this file, also when colcon runs a symlink of it in build/
project = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())
tool = project["tool"]["setuptools"]
src = tool["packages"]["find"]["where"][0]  # "src": the symlink to the repository's src/

setup(
    name=NAME,
    version=project["project"]["version"],
    description=project["project"]["description"],
    license=project["project"]["license"],
    package_dir={"": src},
    packages=find_namespace_packages(src),  # as pyproject.toml's find (namespaces = true): the data folders too
    package_data={"": tool["package-data"]["*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{NAME}"]),
        (f"share/{NAME}", ["package.xml"]),
        (f"share/{NAME}/launch", glob("launch/*.launch.py")),
        (f"share/{NAME}/config", sorted(glob("config/*.params.yaml"))),
    ],
    # the Python libraries come from the ROS installation (package.xml) or pip, not from here
    install_requires=["setuptools"],
    zip_safe=False,
    entry_points={
        "console_scripts": [f"{k} = {v}" for k, v in project["project"]["scripts"].items()],
        **{group: [f"{k} = {v}" for k, v in eps.items()]
           for group, eps in project["project"]["entry-points"].items()},
    },
)
