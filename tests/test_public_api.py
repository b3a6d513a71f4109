"""The public API of each package: ``__all__`` names what users use, each with a numpydoc docstring whose
Examples section runs (docs/architecture.md, "Public API").

The examples run here as doctests, so an example that no longer works fails the suite; so does every other
docstring example in the source (modules of the ROS edge that import rclpy excepted). The cores'
packages re-export lazily (:mod:`phfdi_base.lazy`): importing one must not import scipy & co.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

from phfdi_base.lazy import type_checking_imports

SRC = Path(__file__).resolve().parents[1] / "src"

#: packages with a public API, and whether they re-export lazily (the cores) or eagerly
PACKAGES = {
    "phfdi_base": True, "ph_plant_sim": True, "valve_actuator": True, "pi_controllers": True, "wavelet_fdi": True,
    "phfdi.records": False, "phfdi.diagnosis": True, "phfdi.loopdiag": True, "phfdi.study": True,
    "phfdi.rigsim": False,
}
NAMES = [(p, n) for p in PACKAGES for n in importlib.import_module(p).__all__]
EXAMPLES = re.compile(r"^Examples\n--------\n", re.M)


def _public(package: str, name: str):
    return getattr(importlib.import_module(package), name)


def _documented(package: str, name: str):
    """Where a public name's examples live: its own docstring, or for data (a constant, which has no
    docstring of its own) the package's."""
    obj = _public(package, name)
    return obj if inspect.isclass(obj) or inspect.isroutine(obj) else importlib.import_module(package)


@pytest.mark.parametrize("package", PACKAGES)
def test_package_lists_its_public_names(package):
    names = importlib.import_module(package).__all__
    assert names and len(names) == len(set(names)), f"{package}.__all__ is empty or repeats a name"


@pytest.mark.parametrize(("package", "name"), NAMES, ids=[f"{p}.{n}" for p, n in NAMES])
def test_public_name_exists_with_numpydoc_examples(package, name):
    target = _documented(package, name)
    doc = inspect.getdoc(target) or ""
    assert doc and target.__doc__, f"{package}.{name} has no docstring of its own"
    found = EXAMPLES.search(doc)
    assert found, f"{package}.{name}: its docstring has no numpydoc 'Examples' section"
    assert target is _public(package, name) or name in doc[found.end():], \
        f"{package}.{name}: a constant is shown in the package docstring's Examples section"


@pytest.mark.parametrize(("package", "name"), NAMES, ids=[f"{p}.{n}" for p, n in NAMES])
def test_public_examples_run(package, name):
    tests = doctest.DocTestFinder(recurse=False).find(_documented(package, name), f"{package}.{name}", globs={})
    assert sum(len(t.examples) for t in tests) >= 2, f"{package}.{name}: give a runnable example (>>> lines)"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    for t in tests:
        runner.run(t, out=report.append)
    assert runner.failures == 0, "".join(report)


@pytest.mark.parametrize("package", [p for p, lazy in PACKAGES.items() if lazy])
def test_lazy_exports_match_the_type_checking_imports(package):
    """What mypy and editors see (the ``if TYPE_CHECKING:`` imports) is what ``__all__`` exports."""
    module = importlib.import_module(package)
    assert set(type_checking_imports(module.__file__)) == set(module.__all__)


def test_unknown_name_is_an_attribute_error():
    import wavelet_fdi

    with pytest.raises(AttributeError, match="has no attribute 'no_such_name'"):
        wavelet_fdi.no_such_name  # noqa: B018


def test_importing_the_cores_stays_cheap():
    """The re-exports are lazy: importing the packages loads none of the heavy libraries their modules use."""
    code = ("import sys, phfdi_base, ph_plant_sim, valve_actuator, pi_controllers, wavelet_fdi; "
            "print(sorted(m for m in ('scipy', 'pywt', 'pydantic', 'matplotlib', 'numpy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def _modules_with_examples() -> list[str]:
    """Every module of the project's packages whose source holds a ``>>>`` example, except those that import
    rclpy (the ROS edge runs in its own processes, tests/ros)."""
    out = []
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC)
        if not (SRC / rel.parts[0] / "__init__.py").exists():
            continue
        text = path.read_text(encoding="utf-8")
        if ">>>" in text and not re.search(r"^\s*(import|from) rclpy", text, re.M):
            parts = rel.with_suffix("").parts
            out.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


@pytest.mark.parametrize("module", _modules_with_examples())
def test_every_docstring_example_runs(module):
    mod = importlib.import_module(module)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    for t in doctest.DocTestFinder().find(mod, module):
        runner.run(t, out=report.append)
    assert runner.tries > 0, f"{module}: its '>>>' lines are not in a docstring"
    assert runner.failures == 0, "".join(report)

