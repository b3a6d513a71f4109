"""Public names of a package, imported from their submodules on first use (PEP 562).

Each package of the project lists what users use in ``__all__`` and re-exports it from the module that
defines it, so ``from valve_actuator import Valve`` works. The re-export is lazy: importing the package
imports none of its submodules, so a node that needs one module does not pay for the rest (scipy,
PyWavelets, pydantic). The package names its exports once, as imports under ``if TYPE_CHECKING:`` (what
mypy and editors read); :func:`lazy_exports` reads the same lines to know where each name lives. This is
the pattern of SPEC 1 (scientific-python ``lazy_loader``'s ``attach_stub``), in a few lines.
"""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path
from typing import Any, Callable

__all__ = ["lazy_exports"]


def type_checking_imports(init_file: str | Path) -> dict[str, tuple[str, str]]:
    """Public name -> (relative module, name in it), from the ``if TYPE_CHECKING:`` block of a file.

    Examples
    --------
    >>> import valve_actuator
    >>> type_checking_imports(valve_actuator.__file__)["Valve"]
    ('.valve', 'Valve')
    """
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"))
    out = {}
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for imp in node.body:
                if isinstance(imp, ast.ImportFrom):
                    module = "." * imp.level + (imp.module or "")
                    out.update({a.asname or a.name: (module, a.name) for a in imp.names})
    return out


def lazy_exports(package: str, init_file: str | Path) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for a package that re-exports names of its submodules.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    init_file : str or Path
        The package's ``__init__.py`` (``__file__``): its ``if TYPE_CHECKING:`` imports say which module
        defines each public name. A public name must not be the name of a submodule (importing the
        submodule would replace it on the package).

    Returns
    -------
    __getattr__, __dir__ : callables
        Assign them at the package's top level. A name is imported on first access and then cached on
        the package; an unknown name raises ``AttributeError`` as usual.

    Examples
    --------
    >>> import valve_actuator
    >>> "Valve" in dir(valve_actuator)
    True
    >>> valve_actuator.Valve.__module__
    'valve_actuator.valve'
    """
    exports = type_checking_imports(init_file)

    def __getattr__(name: str) -> Any:
        try:
            module, attr = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        value = getattr(importlib.import_module(module, package), attr)
        setattr(sys.modules[package], name, value)  # later look-ups find it without __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__
