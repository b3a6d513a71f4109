"""Reading the small YAML files users hand us (scenarios, plant models, column maps): one clear error each."""

from __future__ import annotations

from pathlib import Path

import yaml

from .errors import UserError


def read_mapping(path: str | Path, what: str = "file", expected: str = "a mapping at the top level") -> dict:
    """The YAML mapping in ``path``; a :class:`UserError` naming the file and the problem otherwise.

    ``what`` names the file in the not-found message ("no such column map: ..."); ``expected`` says what the
    top level must be when it is not a mapping.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi_base import UserError, read_mapping
    >>> path = Path(tempfile.mkdtemp()) / "loop.yaml"
    >>> _ = path.write_text("duration_s: 600")
    >>> read_mapping(path)
    {'duration_s': 600}
    >>> _ = path.write_text("- a list")
    >>> try:
    ...     read_mapping(path)
    ... except UserError as exc:
    ...     print(str(exc).endswith("expected a mapping at the top level"))
    True
    """
    try:
        with open(path, encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    except (FileNotFoundError, IsADirectoryError):
        raise UserError(f"no such {what}: {path}") from None
    except UnicodeDecodeError as exc:
        line = exc.object.count(b"\n", 0, exc.start) + 1
        raise UserError(f"{path}: line {line}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x})") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or "parse error"
        raise UserError(f"{path}: not valid YAML{where} ({problem})") from None
    except (ValueError, OverflowError) as exc:  # a scalar YAML types but cannot build, e.g. date 2024-13-45
        raise UserError(f"{path}: not valid YAML (a value cannot be read: {exc})") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected {expected}")
    return data


def list_presets(directory: Path) -> dict[str, str]:
    """name -> first line of the description of each YAML preset in a directory (``faults.yaml`` left out)."""
    out = {}
    for p in sorted(directory.glob("*.yaml")):
        if p.stem == "faults":
            continue
        lines = str(read_mapping(p).get("description", "")).strip().splitlines()
        out[p.stem] = lines[0] if lines else ""
    return out


def resolve_preset(name_or_path: str, directory: Path, kind: str) -> Path:
    """A .yaml/.yml path as given, or the preset of that name in ``directory``; a :class:`UserError` listing
    the presets otherwise."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        return p
    candidate = directory / f"{name_or_path}.yaml"
    if not candidate.exists():
        known = ", ".join(list_presets(directory))
        raise UserError(f"unknown {kind} {name_or_path!r}; presets: {known} (or give a .yaml path)")
    return candidate
