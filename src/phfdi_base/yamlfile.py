"""Reading the small YAML files users hand us (scenarios, plant models, column maps): one clear error each."""

from __future__ import annotations

from pathlib import Path

import yaml

from .errors import UserError
from .files import not_a_file


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
    raw = _small_bytes(path, what)
    try:
        text = raw.decode("utf-8")
        if any(isinstance(e, yaml.AliasEvent) for e in yaml.parse(text, Loader=yaml.SafeLoader)):
            # an alias repeats a node: nine nested ones expand a 1 kB file to a gigabyte ("billion laughs")
            raise UserError(f"{path}: YAML aliases (*name) are not accepted in this file; write the values out")
        data = yaml.safe_load(text)
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


#: the largest YAML file read (scenarios, plant models and column maps are a few kB)
MAX_YAML_BYTES = 1 << 20


def _small_bytes(path: str | Path, what: str) -> bytes:
    """The file's bytes: a regular file (a FIFO would block), at most MAX_YAML_BYTES."""
    why = not_a_file(path)
    if why == "no such file":
        raise UserError(f"no such {what}: {path}")
    if why == "a folder, not a file":
        raise UserError(f"no such {what}: {path} (a folder)")
    if why is not None:
        raise UserError(f"{path}: {why}")
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            data = fh.read(MAX_YAML_BYTES + 1)
    except OSError as exc:
        raise UserError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    if len(data) > MAX_YAML_BYTES:
        raise UserError(f"{path}: larger than {MAX_YAML_BYTES >> 20} MiB: not a {what}")
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
