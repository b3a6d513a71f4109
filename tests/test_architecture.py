"""The floors of the project run one way (docs/architecture.md), checked on the source with ast.

Every ``import`` counts, at module level or inside a function: an import hidden in a function is still a
dependency. The checks fail when violated; the tests at the end plant violations in a scratch tree and require
the checker to find them.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

#: top-level package -> floor. A package may import its own floor's modules and any lower floor, except that
#: the three plant-side cores (floor 1) do not import each other; wavelet_fdi (floor 2) may import them.
FLOORS = {
    "phfdi_base": 0,
    "ph_plant_sim": 1,
    "valve_actuator": 1,
    "pi_controllers": 1,
    "wavelet_fdi": 2,
    "phfdi": 3,
}

#: edges (importing module -> imported module) allowed to go up a floor while a move is in progress (issue 14
#: emptied it). It may only shrink: an edge that no longer exists fails the test below.
KNOWN_UPWARD: frozenset[tuple[str, str]] = frozenset()
#: circles between files still to be broken (same rule: may only shrink; issue 14 emptied it: run files are read by
#: phfdi.records.read_run, bags by phfdi.bagread.load_bag, and phfdi.bagio.load_run dispatches between the two).
KNOWN_CYCLES: tuple[tuple[str, ...], ...] = ()


@dataclass(frozen=True)
class Edge:
    source: str  # importing module, dotted
    target: str  # imported module of the project, dotted
    line: int

    @property
    def packages(self) -> tuple[str, str]:
        return self.source.split(".")[0], self.target.split(".")[0]


def module_name(path: Path, src: Path) -> str:
    parts = list(path.relative_to(src).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def project_modules(src: Path) -> dict[str, Path]:
    """Every module under ``src`` (packages are directories with an ``__init__.py``)."""
    out = {}
    for path in src.rglob("*.py"):
        rel = path.relative_to(src)
        if all((src / Path(*rel.parts[:i]) / "__init__.py").exists() for i in range(1, len(rel.parts))):
            out[module_name(path, src)] = path
    return out


def _imported(node: ast.AST, module: str, is_package: bool, modules: dict[str, Path]) -> list[str]:
    """Names a statement imports; ``from pkg import sub`` names the submodule, not the package."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = module.split(".")
            base = base[: len(base) - node.level + (1 if is_package else 0)]
            target = ".".join(base + ([node.module] if node.module else []))
        else:
            target = node.module or ""
        return [f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target for a in node.names]
    return []


def import_edges(src: Path) -> list[Edge]:
    """Module -> project module edges, resolved to the longest existing module name."""
    modules = project_modules(src)
    edges: set[Edge] = set()
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            for name in _imported(node, module, path.name == "__init__.py", modules):
                while name and name not in modules:
                    name = name.rpartition(".")[0]
                if name and name != module:
                    edges.add(Edge(module, name, node.lineno))
    return sorted(edges, key=lambda e: (e.source, e.target, e.line))


def floor_violations(edges: list[Edge], floors: dict[str, int] = FLOORS) -> list[str]:
    """Edges that go up a floor (or sideways between plant-side cores), and packages without a floor."""
    out = []
    for e in edges:
        a, b = e.packages
        if a == b:
            continue
        for p in (a, b):
            if p not in floors:
                out.append(f"{p}: no floor declared in tests/test_architecture.py FLOORS")
        if a not in floors or b not in floors:
            continue
        if floors[b] > floors[a] or (floors[b] == floors[a] == 1):
            out.append(f"{e.source} (line {e.line}) imports {e.target}: {a} (floor {floors[a]}) may not import "
                       f"{b} (floor {floors[b]})")
    return sorted(set(out))


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def module_graph(edges: list[Edge]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for e in edges:
        graph.setdefault(e.source, set()).add(e.target)
    return graph


def package_graph(edges: list[Edge]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {}
    for e in edges:
        a, b = e.packages
        if a != b:
            graph.setdefault(a, set()).add(b)
    return graph


# ---- the project -------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def edges() -> list[Edge]:
    return import_edges(SRC)


def test_every_package_has_a_floor():
    packages = {p.name for p in SRC.iterdir() if (p / "__init__.py").exists()}
    assert packages == set(FLOORS), "declare the floor of each package in FLOORS (and in docs/architecture.md)"


def test_no_import_goes_up_a_floor(edges):
    left = [e for e in edges if (e.source, e.target) not in KNOWN_UPWARD]
    assert floor_violations(left) == []


def test_known_exceptions_still_exist(edges):
    present = {(e.source, e.target) for e in edges}
    assert sorted(KNOWN_UPWARD - present) == [], "these edges are gone: remove them from KNOWN_UPWARD"


def test_no_package_cycle(edges):
    assert cycles(package_graph([e for e in edges if (e.source, e.target) not in KNOWN_UPWARD])) == []


def test_no_module_cycle(edges):
    found = [tuple(c) for c in cycles(module_graph(edges))]
    assert [c for c in found if c not in KNOWN_CYCLES] == []
    assert [c for c in KNOWN_CYCLES if c not in found] == [], "these circles are gone: remove them from KNOWN_CYCLES"


# ---- the checker finds planted violations -------------------------------------------------------------------
def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return tmp_path


PLANTED = {
    "phfdi_base/__init__.py": "",
    "phfdi_base/blocks.py": "",
    "valve_actuator/__init__.py": "",
    "valve_actuator/valve.py": "from phfdi_base.blocks import *\n",
    "ph_plant_sim/__init__.py": "",
    "ph_plant_sim/plant.py": "def f():\n    from phfdi.loop import tick\n",  # hidden in a function
    "pi_controllers/__init__.py": "",
    "pi_controllers/pi.py": "import valve_actuator.valve\n",  # sideways between plant-side cores
    "wavelet_fdi/__init__.py": "",
    "wavelet_fdi/detector.py": "from ph_plant_sim import plant\nfrom .a import x\n",
    "wavelet_fdi/a.py": "from . import detector\nx = 1\n",  # a circle between two files
    "phfdi/__init__.py": "",
    "phfdi/loop.py": "from ph_plant_sim.plant import *\n",
}


def test_checker_catches_a_core_importing_the_application(tmp_path):
    found = floor_violations(import_edges(_tree(tmp_path, PLANTED)))
    assert any(v.startswith("ph_plant_sim.plant (line 2) imports phfdi.loop") for v in found), found
    assert any(v.startswith("pi_controllers.pi (line 1) imports valve_actuator.valve") for v in found), found
    assert not any(v.startswith(("valve_actuator.valve", "wavelet_fdi.", "phfdi.loop")) for v in found), found


def test_checker_catches_cycles(tmp_path):
    edges = import_edges(_tree(tmp_path, PLANTED))
    assert ["wavelet_fdi.a", "wavelet_fdi.detector"] in cycles(module_graph(edges))
    assert cycles(package_graph(edges)) == [["ph_plant_sim", "phfdi"]]


def test_checker_asks_for_a_floor_for_a_new_package(tmp_path):
    files = dict(PLANTED, **{"newpkg/__init__.py": "import phfdi_base.blocks\n"})
    assert "newpkg: no floor declared in tests/test_architecture.py FLOORS" in floor_violations(
        import_edges(_tree(tmp_path, files)))


# ---- the application's inner floors ---------------------------------------------------------------------------
#: phfdi's parts (its modules and subpackages) -> inner floor, same rule as FLOORS one level in: a part imports its
#: own inner floor and the ones below, never one above (docs/architecture.md, "The application's inner floors").
PHFDI_FLOORS = {
    # 0 a run and its files, the fault vocabulary of the application
    "bagread": 0, "rosbag2_meta": 0, "records": 0, "bagio": 0, "faults": 0, "inject_kinds": 0,
    "summary": 0, "figures": 0, "alarm_text": 0,
    # 1 the loop: scenarios, the in-process simulation, replay's reading side, the ROS graph
    "scenario": 1, "loop": 1, "replay": 1, "ros": 1,
    # 2 measured data: learned and estimator references, injected faults, the simulated rig, diagnosis
    "learned": 2, "estimator": 2, "inject": 2, "rigsim": 2, "diagnosis": 2, "loopdiag": 2,
    # 3 evaluation: the paper's study, the benchmarks' shared code
    "study": 3, "benchmarks": 3,
    # 4 the command line
    "commands": 4, "cli": 4, "console": 4,
}


def phfdi_part(module: str) -> str | None:
    """The part of phfdi a module belongs to (``phfdi.records.sources`` -> ``records``); None outside phfdi's parts."""
    parts = module.split(".")
    return parts[1] if parts[0] == "phfdi" and len(parts) > 1 else None


def phfdi_parts(src: Path) -> set[str]:
    root = src / "phfdi"
    return {p.stem for p in root.glob("*.py") if p.stem != "__init__"} | {
        p.name for p in root.iterdir() if (p / "__init__.py").exists()}


def inner_floor_violations(edges: list[Edge], floors: dict[str, int] = PHFDI_FLOORS) -> list[str]:
    """Edges between phfdi's parts that go up an inner floor, and parts without an inner floor."""
    out = []
    for e in edges:
        a, b = phfdi_part(e.source), phfdi_part(e.target)
        if a is None or b is None or a == b:
            continue
        missing = [p for p in (a, b) if p not in floors]
        out += [f"phfdi.{p}: no inner floor declared in tests/test_architecture.py PHFDI_FLOORS" for p in missing]
        if not missing and floors[b] > floors[a]:
            out.append(f"{e.source} (line {e.line}) imports {e.target}: phfdi.{a} (inner floor {floors[a]}) may "
                       f"not import phfdi.{b} (inner floor {floors[b]})")
    return sorted(set(out))


def test_every_part_of_the_application_has_an_inner_floor():
    assert phfdi_parts(SRC) == set(PHFDI_FLOORS), "declare the inner floor of each part in PHFDI_FLOORS (and docs)"


def test_no_import_goes_up_an_inner_floor(edges):
    assert inner_floor_violations(edges) == []


def test_inner_floor_checker_catches_an_import_up_and_a_part_without_a_floor(tmp_path):
    files = {"phfdi/__init__.py": "", "phfdi/records.py": "def f():\n    from phfdi.commands import replay\n",
             "phfdi/commands/__init__.py": "", "phfdi/commands/replay.py": "from phfdi.records import f\n",
             "phfdi/newpart.py": "import phfdi.records\n"}
    found = inner_floor_violations(import_edges(_tree(tmp_path, files)))
    assert any(v.startswith("phfdi.records (line 2) imports phfdi.commands.replay: phfdi.records (inner floor 0)")
               for v in found), found
    assert "phfdi.newpart: no inner floor declared in tests/test_architecture.py PHFDI_FLOORS" in found
    assert not any(v.startswith("phfdi.commands.replay") for v in found), found  # down is allowed


# ---- short functions ------------------------------------------------------------------------------------------
MAX_FUNCTION_LINES = 80
#: functions still longer than MAX_FUNCTION_LINES (file, name): may only shrink, as KNOWN_UPWARD
KNOWN_LONG: frozenset[tuple[str, str]] = frozenset({
})


def long_functions(src: Path, limit: int = MAX_FUNCTION_LINES) -> set[tuple[str, str]]:
    """(file relative to ``src``, function name) of every function or method longer than ``limit`` lines."""
    out = set()
    for path in src.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno - node.lineno + 1 > limit:
                out.add((path.relative_to(src).as_posix(), node.name))
    return out


def test_no_function_over_80_lines():
    found = long_functions(SRC)
    assert sorted(found - KNOWN_LONG) == [], f"split these into functions of at most {MAX_FUNCTION_LINES} lines"
    assert sorted(KNOWN_LONG - found) == [], "these are short now: remove them from KNOWN_LONG"


def test_length_checker_catches_a_long_function(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    _tree(tmp_path, {"pkg/__init__.py": "", "pkg/m.py": f"def short():\n    pass\n\n\ndef long():\n{body}"})
    assert long_functions(tmp_path) == {("pkg/m.py", "long")}


# ---- one fault catalogue ----------------------------------------------------------------------------------------
#: modules that still define a fault parameter's search range themselves instead of reading the catalogue
#: (issue 14 emptied it): may only shrink, as KNOWN_UPWARD
KNOWN_OWN_BOUNDS: frozenset[str] = frozenset()


def _registers_faults(tree: ast.AST) -> bool:
    """True for a module that declares faults: ``register_block(..., fault=...)`` or ``Fault(...)``."""
    return any(isinstance(n, ast.Call) and (any(k.arg == "fault" for k in n.keywords)
                                            or getattr(n.func, "id", "") == "Fault") for n in ast.walk(tree))


def _is_number(node: ast.AST) -> bool:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        node = node.operand
    return isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool)


def _strings(call: ast.Call) -> tuple[list[str], bool]:
    args = list(call.args) + [k.value for k in call.keywords]
    return [a.value for a in args if isinstance(a, ast.Constant) and isinstance(a.value, str)], any(map(_is_number, args))


def _draws_a_range(value: ast.AST) -> bool:
    """A value drawn over a range written out: a call with two numbers (``logu(rng, 0.3, 6.0)``) within it."""
    return any(isinstance(c, ast.Call) and sum(map(_is_number, c.args)) >= 2 for c in ast.walk(value))


def _named_with_number(sub: ast.AST, in_call: bool) -> tuple[list[str], bool]:
    """Strings a call names and whether a number goes with them; within a tuple such as a valve
    ``("backlash", {"width_pct": logu(rng, 0.3, 6.0)})`` also a dict's keys whose values draw over a range."""
    if isinstance(sub, ast.Call):
        return _strings(sub)
    if isinstance(sub, ast.Dict) and not in_call:
        drawn = [k.value for k, v in zip(sub.keys, sub.values) if isinstance(k, ast.Constant)
                 and isinstance(k.value, str) and _draws_a_range(v)]
        return drawn, bool(drawn)
    return [], False


def _container_strings(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Call):
        return _strings(node)[0]
    if isinstance(node, (ast.Tuple, ast.List)):
        return [e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)]
    return []


def own_fault_bounds(src: Path, params: dict[str, set[str]], vocabulary: str = "") -> dict[str, list[str]]:
    """module -> places outside the modules that declare faults (and the loop diagnosis's declared
    ``vocabulary``) where a call or a tuple names a catalogued fault (its name or block, e.g.
    ``Candidate("backlash", ...)``, ``("backlash", {...})``) and, within it, a call names one of that fault's
    parameters next to a number (``Param("width_pct", 0.02, 20.0)``) or, within a tuple, a dict draws it over a
    range written out (``{"width_pct": logu(rng, 0.3, 6.0)}``; a fixed value is no bound): a bound defined a
    second time. ``params``: fault name or block -> its parameter names."""
    out: dict[str, set[str]] = {}
    for module, path in project_modules(src).items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if _registers_faults(tree) or module == vocabulary:
            continue
        for node in ast.walk(tree):
            for fault in set(_container_strings(node)) & set(params):
                for sub in ast.walk(node):
                    names, number = _named_with_number(sub, isinstance(node, ast.Call))
                    named = [n for n in names if n in params[fault]]
                    if named and number:
                        out.setdefault(module, set()).add(f"line {sub.lineno}: {fault}.{named[0]}")
    return {m: sorted(v) for m, v in out.items()}


def _catalogued_params() -> dict[str, set[str]]:
    from phfdi.faults import catalogue

    out: dict[str, set[str]] = {}
    for f in catalogue().values():
        for key in (f.name, f.block):
            out.setdefault(key, set()).update(p.name for p in f.params)
    return out


#: the loop diagnosis's own vocabulary (its cause lists; the causes' ranges in % of each loop's OP span are declared
#: with each fault in the catalogue, ``loop=LoopDraws(...)``, and read there: docs/architecture.md)
LOOP_VOCABULARY = "phfdi.loopdiag.vocabulary"


def test_fault_parameters_are_bounded_only_in_the_catalogue():
    found = own_fault_bounds(SRC, _catalogued_params())  # the loop diagnosis's vocabulary included
    assert {m: v for m, v in found.items() if m not in KNOWN_OWN_BOUNDS} == {}, \
        "read the bounds from the fault catalogue (phfdi_base.faults, declared with the block)"
    assert sorted(KNOWN_OWN_BOUNDS - set(found)) == [], "these read the catalogue now: remove them from KNOWN_OWN_BOUNDS"


def test_bounds_checker_catches_a_second_definition(tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": "",
                     "pkg/blocks.py": 'X = Fault("b", params=(FaultParam("width_pct", "%", (0, 100)),))\n',
                     "pkg/fit.py": 'C = [Candidate("backlash", [Param("width_pct", 0.02, 20.0, "%")]),\n'
                                   '     Candidate("backlash", [Param("width_pct", lo, hi)]),\n'
                                   '     Candidate("feed_delay", [Param("width_pct", 0.0, 9.0)])]\n',
                     "pkg/iso.py": 'H = Hypothesis("backlash", "backlash", "width_pct", "% of span", 0.05, 20.0)\n',
                     "pkg/train.py": 'def draw(rng):\n    return ("backlash", {"width_pct": logu(rng, 0.3, 6.0)})\n'
                                     'CASE = ("backlash", {"width_pct": 2.0})\n',
                     "pkg/vocabulary.py": 'D = [("backlash", {"width_pct": (0.3, 6.0)})]\n'})
    assert own_fault_bounds(tmp_path, {"backlash": {"width_pct"}}, "pkg.vocabulary") == {
        "pkg.fit": ["line 1: backlash.width_pct"], "pkg.iso": ["line 1: backlash.width_pct"],
        "pkg.train": ["line 2: backlash.width_pct"]}


def loop_cause_lists(src: Path, causes: set[str], vocabulary: str = LOOP_VOCABULARY) -> dict[str, list[str]]:
    """module -> lines in the loop diagnosis (the package of ``vocabulary``) outside the vocabulary with a tuple,
    list or set of two or more loop causes' names and nothing else (a cause list written again)."""
    out: dict[str, list[str]] = {}
    package = vocabulary.rpartition(".")[0]
    for module, path in project_modules(src).items():
        if module == vocabulary or not module.startswith(package + "."):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set)) and len(node.elts) >= 2 and all(
                    isinstance(e, ast.Constant) and e.value in causes for e in node.elts):
                out.setdefault(module, []).append(f"line {node.lineno}")
    return out


def test_the_loop_diagnosis_names_its_causes_in_its_vocabulary_only():
    """Loop diagnosis declares its cause lists once (phfdi.loopdiag.vocabulary) and no other module lists them
    again; every cause, and every valve its training loops draw, is a catalogued fault whose entry declares the
    draws (``loop=LoopDraws``) over its block's own parameters."""
    from phfdi.faults import catalogue
    from phfdi.loopdiag.hammerstein import FITTERS
    from phfdi.loopdiag.vocabulary import (
        ACTUATOR_CAUSES,
        DOMAIN_DRAWS,
        FRICTION_CAUSES,
        OTHER_NONLINEARITIES,
        TRAINING_DRAWS,
    )

    causes = set(ACTUATOR_CAUSES)
    assert set(FITTERS) == causes and set(FRICTION_CAUSES) | set(OTHER_NONLINEARITIES) == causes
    drawn = {f.block: f for f in catalogue().values() if f.loop is not None}
    assert causes <= set(TRAINING_DRAWS) <= set(drawn), "every loop cause is a catalogued fault with its draws"
    assert set(OTHER_NONLINEARITIES) <= set(DOMAIN_DRAWS) <= set(drawn)
    for cause, draws in [*TRAINING_DRAWS.items(), *DOMAIN_DRAWS.items()]:
        own = {k for k in draws if k.endswith("_pct")}
        assert own <= {p.name for p in drawn[cause].params}, f"{cause}: {own} are not its catalogued parameters"
    assert loop_cause_lists(SRC, causes | {"stiction_he"}) == {}


def test_cause_list_checker_catches_a_second_list(tmp_path):
    _tree(tmp_path, {"pkg/__init__.py": "", "pkg/vocabulary.py": 'C = ("backlash", "stiction")\n',
                     "pkg/eval.py": 'F = ("stiction", "backlash")\nL = ("stiction", "healthy")\n'})
    assert loop_cause_lists(tmp_path, {"backlash", "stiction"}, "pkg.vocabulary") == {"pkg.eval": ["line 1"]}


# ---- one reader of run and record files ----------------------------------------------------------------------
#: the suffixes of record files (runs, bags, historian exports); see phfdi.records.formats
RECORD_SUFFIXES = frozenset({".csv", ".parquet", ".pq", ".mcap", ".txt", ".tsv"})
#: the modules that may decide on a record file's suffix: the registry and readers, the bag reader below them
#: (the writers are Record.save and its own)
FILE_FORMAT_MODULES = ("phfdi.records", "phfdi.bagread")


def suffix_decisions(src: Path, allowed: tuple[str, ...] = FILE_FORMAT_MODULES) -> dict[str, list[str]]:
    """module -> lines outside ``allowed`` that compare a path's ``suffix`` with a record file's suffix (a
    reader or a file list chosen by extension, where the registry phfdi.records.formats should be asked)."""
    out: dict[str, list[str]] = {}
    for module, path in project_modules(src).items():
        if module.startswith(tuple(f"{a}." for a in allowed)) or module in allowed:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Compare):
                continue
            subs = [s for side in (node.left, *node.comparators) for s in ast.walk(side)]
            if any(isinstance(s, ast.Attribute) and s.attr == "suffix" for s in subs) and any(
                    isinstance(s, ast.Constant) and s.value in RECORD_SUFFIXES for s in subs):
                out.setdefault(module, []).append(f"line {node.lineno}")
    return out


def test_record_files_are_told_apart_only_by_the_format_registry():
    assert suffix_decisions(SRC) == {}, \
        "ask phfdi.records.formats (format_of, is_format, run_suffixes, historian_suffixes) instead"


def test_suffix_checker_catches_a_reader_of_its_own(tmp_path):
    _tree(tmp_path, {"phfdi/__init__.py": "", "phfdi/records/__init__.py": "",
                     "phfdi/records/sources.py": 'def f(p):\n    return p.suffix == ".csv"\n',
                     "phfdi/tool.py": 'def f(p):\n    if p.suffix.lower() in (".csv", ".pq"):\n        pass\n'
                                      '    return p.suffix == ".yaml"\n'})
    assert suffix_decisions(tmp_path) == {"phfdi.tool": ["line 2"]}


#: functions that read a table of samples from a file; only the record readers call them
TABLE_READERS = frozenset({"read_csv", "read_parquet", "read_table", "loadtxt", "genfromtxt", "reader", "DictReader"})
#: modules beside the readers that call one, each for something that is not a run: the wide export's header
#: line (its loops are then read by phfdi.records), the labels file of a loop collection
NOT_A_RUN = {"phfdi.loopdiag.plantwide": "a wide export's header line",
             "phfdi.loopdiag.evaluate": "labels.csv of a loop collection"}


def table_reads(src: Path, allowed: tuple[str, ...] = FILE_FORMAT_MODULES) -> dict[str, list[str]]:
    """module -> lines outside ``allowed`` and :data:`NOT_A_RUN` that call a table reader (pandas, numpy, csv,
    pyarrow): a second reader of runs, where phfdi.records.read_run should be asked."""
    out: dict[str, list[str]] = {}
    for module, path in project_modules(src).items():
        if module.startswith(tuple(f"{a}." for a in allowed)) or module in allowed or module in NOT_A_RUN:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in TABLE_READERS:
                out.setdefault(module, []).append(f"line {node.lineno}")
    return out


def test_runs_are_read_only_by_the_record_readers():
    assert table_reads(SRC) == {}, "read runs with phfdi.records.read_run (or add a reader to phfdi.records)"


def test_table_read_checker_catches_a_reader_of_its_own(tmp_path):
    _tree(tmp_path, {"phfdi/__init__.py": "", "phfdi/records/__init__.py": "",
                     "phfdi/records/csvfile.py": "import pandas as pd\ndef f(p):\n    return pd.read_csv(p)\n",
                     "phfdi/tool.py": "import numpy as np\ndef f(p):\n    return np.loadtxt(p, delimiter=',')\n"})
    assert table_reads(tmp_path) == {"phfdi.tool": ["line 3"]}


#: the one in-memory record (issue 37: a simulated run and a read file alike): a second class of that kind is a
#: record type more to learn
RECORD_CLASS = ("phfdi.records.record", "Record")


def record_classes(src: Path) -> dict[str, list[str]]:
    """module -> classes named ``...Record`` (or ``Run``, the run type it replaced) other than :data:`RECORD_CLASS`:
    a second in-memory record type,
    where :class:`phfdi.records.Record` should carry the view (``inputs``/``outputs``, ``x``, ``on_grid``...)."""
    out: dict[str, list[str]] = {}
    for module, path in project_modules(src).items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (isinstance(node, ast.ClassDef) and (node.name.endswith("Record") or node.name == "Run")
                    and (module, node.name) != RECORD_CLASS):
                out.setdefault(module, []).append(f"{node.name} (line {node.lineno})")
    return out


def test_one_in_memory_record_type():
    assert record_classes(SRC) == {}, "use phfdi.records.Record (add the view the new code needs to it)"


def test_record_class_checker_catches_a_second_record(tmp_path):
    _tree(tmp_path, {"phfdi/__init__.py": "", "phfdi/records/__init__.py": "",
                     "phfdi/records/record.py": "class Record:\n    pass\n",
                     "phfdi/tool.py": "import dataclasses\n@dataclasses.dataclass\nclass MeasuredRecord:\n    x: int\n",
                     "phfdi/sim.py": "class Run:\n    pass\n"})
    assert record_classes(tmp_path) == {"phfdi.tool": ["MeasuredRecord (line 3)"], "phfdi.sim": ["Run (line 1)"]}


#: the delimiters a hand-written table parser splits its lines on
DELIMITERS = frozenset({";", ",", "\t", "|"})


def hand_split_tables(src: Path, allowed: tuple[str, ...] = FILE_FORMAT_MODULES) -> dict[str, list[str]]:
    """module -> functions outside the format modules that split a text's lines and then each line on a
    delimiter: a table parsed by hand (SKAB's files were, until they went through read_record)."""
    out: dict[str, list[str]] = {}
    for module, path in project_modules(src).items():
        if module.startswith(tuple(f"{a}." for a in allowed)) or module in allowed:
            continue
        for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            calls = [n for n in ast.walk(fn) if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)]
            lines = any(c.func.attr == "splitlines" for c in calls)
            cells = [c for c in calls if c.func.attr == "split" and c.args and isinstance(c.args[0], ast.Constant)
                     and c.args[0].value in DELIMITERS]
            if lines and cells:
                out.setdefault(module, []).append(f"{fn.name} (line {cells[0].lineno})")
    return out


def test_no_table_is_parsed_by_hand():
    assert hand_split_tables(SRC) == {}, "read the file with phfdi.records.read_record (a format of its own: " \
                                         "register_format)"


def test_hand_split_checker_catches_a_parser_of_its_own(tmp_path):
    parser = "def read(p):\n    rows = [ln.split(';') for ln in p.read_text().splitlines()]\n    return rows\n"
    _tree(tmp_path, {"phfdi/__init__.py": "", "phfdi/records/__init__.py": "", "phfdi/records/text.py": parser,
                     "phfdi/bench.py": parser, "phfdi/words.py": "def f(s):\n    return s.split(',')\n"})
    assert hand_split_tables(tmp_path) == {"phfdi.bench": ["read (line 2)"]}


# ---- detector settings declared once ---------------------------------------------------------------------
#: modules with options of the same name that are not the detector's: the paper's offline wavelet analysis
OWN_WAVELET_OPTIONS = {"phfdi.commands.analyze": "the offline analysis's wavelet and level"}


def setting_redeclarations(src: Path, names: set[str], flags: set[str],
                           home: str = "wavelet_fdi.config") -> dict[str, list[str]]:
    """module -> lines outside ``home`` that declare a detector setting again: an ``add_argument`` of one of
    its option flags or a ``ParamSpec`` of its name (both are derived from LearnedSettings' declaration)."""
    out: dict[str, list[str]] = {}
    for module, path in project_modules(src).items():
        if module == home or module in OWN_WAVELET_OPTIONS:
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)):
                continue
            func = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            first = node.args[0].value
            if (func == "add_argument" and first in flags) or (func == "ParamSpec" and first in names):
                out.setdefault(module, []).append(f"line {node.lineno}")
    return out


def test_detector_settings_are_declared_once():
    from wavelet_fdi.config import setting_specs

    specs = setting_specs()
    assert setting_redeclarations(SRC, {s.name for s in specs}, {s.flag for s in specs}) == {}, \
        "declare a detector setting in wavelet_fdi.config.LearnedSettings (setting(...)); derive the rest"


def test_settings_checker_catches_a_second_declaration(tmp_path):
    _tree(tmp_path, {"wavelet_fdi/__init__.py": "", "wavelet_fdi/config.py": "",
                     "wavelet_fdi/node.py": 'P = (ParamSpec("arl0_samples", 1e5, "target"),)\n',
                     "phfdi/__init__.py": "",
                     "phfdi/cli.py": 'def f(p):\n    p.add_argument("--arl0", type=float)\n'
                                     '    p.add_argument("--out")\n'})
    assert setting_redeclarations(tmp_path, {"arl0_samples"}, {"--arl0"}) == {
        "wavelet_fdi.node": ["line 1"], "phfdi.cli": ["line 2"]}
