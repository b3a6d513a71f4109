"""ament_python package phfdi_ros: the graph's nodes from the repository's src/, for `colcon build`.

Why a package of its own here and not a setup.py at the repository root: the root keeps its pyproject.toml for
`pip install -e .` (scripts/setup.sh) untouched, and colcon, crawling a workspace, finds this package.xml (and
interfaces/phfdi_interfaces) but no package at the root. The code is not copied: this setup.py builds the
packages of ../../src, and takes the console scripts, the ``phfdi.node_parts`` entry point and the package data
from ../../pyproject.toml, so the executables are the same entry points as `pip install` makes.
"""

import tomllib
from glob import glob
from pathlib import Path

from setuptools import find_namespace_packages, setup

NAME = "phfdi_ros"
ROOT = "../.."  # the repository; relative, as setuptools wants (colcon runs this file from its folder)
project = tomllib.loads(Path(ROOT, "pyproject.toml").read_text())
tool = project["tool"]["setuptools"]
src = f"{ROOT}/{tool['packages']['find']['where'][0]}"

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
        (f"share/{NAME}/config", sorted(glob(f"{ROOT}/config/*.params.yaml"))),
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
