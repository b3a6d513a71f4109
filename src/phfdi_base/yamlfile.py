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
    except UnicodeDecodeError as exc:
        line = exc.object.count(b"\n", 0, exc.start) + 1
        raise UserError(f"{path}: line {line}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x})") from None
    data = load_yaml(text, path)
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected {expected}")
    return data


def load_yaml(text: str, source: object) -> object:
    """``text`` parsed as YAML, strictly: no aliases, no key twice in one mapping; a :class:`UserError`
    starting with ``source`` (a file, ``--set KEY``) otherwise. Every YAML the project reads comes through here.

    PyYAML keeps the last of two equal keys without a word, so a column map with ``ph_measured`` twice, or a
    scenario with ``duration_s`` twice, silently used one of them; now the key and both lines are named.

    >>> load_yaml("a: 1\\nb: {c: 2}", "f.yaml")
    {'a': 1, 'b': {'c': 2}}
    >>> try:
    ...     load_yaml("a: 1\\nb: 2\\na: 3\\n", "map.yaml")
    ... except UserError as exc:
    ...     print(exc)
    map.yaml: line 3: key 'a' appears twice in one mapping (first at line 1); YAML would keep only the last: remove one
    """
    try:
        if any(isinstance(e, yaml.AliasEvent) for e in yaml.parse(text, Loader=yaml.SafeLoader)):
            # an alias repeats a node: nine nested ones expand a 1 kB file to a gigabyte ("billion laughs")
            raise UserError(f"{source}: YAML aliases (*name) are not accepted in this file; write the values out")
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader (below)
    except _DuplicateKey as dup:
        first = "earlier on that line" if dup.first_line == dup.line else f"first at line {dup.first_line}"
        raise DuplicateKeyError(f"{source}: line {dup.line}: key {dup.key!r} appears twice in one mapping ({first}); "
                                f"YAML would keep only the last: remove one") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or "parse error"
        raise UserError(f"{source}: not valid YAML{where} ({problem})") from None
    except (ValueError, OverflowError) as exc:  # a scalar YAML types but cannot build, e.g. date 2024-13-45
        raise UserError(f"{source}: not valid YAML (a value cannot be read: {exc})") from None


class DuplicateKeyError(UserError):
    """A YAML mapping names a key twice (the message names the source, the key and both lines)."""


class _DuplicateKey(Exception):
    def __init__(self, key: object, line: int, first_line: int) -> None:
        super().__init__(key)
        self.key, self.line, self.first_line = key, line, first_line


class _StrictLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key that appears twice in one mapping (it keeps the last silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        first: dict = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # '<<: {...}' merges on purpose, the later wins
                continue
            key = self.construct_object(key_node, deep=True)
            line = key_node.start_mark.line + 1
            try:
                if key in first:
                    raise _DuplicateKey(key, line, first[key])
                first[key] = line
            except TypeError:  # an unhashable key: the safe constructor names it
                continue
        return super().construct_mapping(node, deep=deep)


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
