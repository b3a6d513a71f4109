"""Every command the README and the ``--help`` examples show is run or, where that is too long, parsed and checked.

What is extracted:

* README.md: every line of a fenced ``bash`` block (``\\``-continued lines joined, ``S=...`` assignments expanded,
  ``&&``/``;``/``|``/``&`` split into separate commands, ``>`` redirections taken as outputs, ``# comments`` dropped),
  and every inline code span that starts with ``phfdi``, ``.venv/bin/phfdi`` or ``.venv/bin/python``.
* ``phfdi SUBCOMMAND --help``: every ``phfdi ...`` line of each subcommand's ``examples:`` epilog, and every
  ``--set KEY=VALUE`` an option's help text gives as an example.

What every ``phfdi`` command gets (parse check): the real argparse parser of ``phfdi.cli.build_parser`` parses it (a
misspelled subcommand or option fails); a scenario command (simulate, launch, demo, calibrate, analyze) loads its
scenario with its ``--fault``, ``--onset`` and ``--set`` through ``phfdi.scenario.load_scenario`` (a ``--set`` the
scenario refuses fails, e.g. ``duration_s=2000`` with the paper's setpoint change at 5000 s); and the files it reads
must exist:

* README fenced commands: every input file, after ``../shared/data`` is mapped to the ``shared_data`` fixture, exists
  (in the repository or in ../shared/data; globs must match) or is written by an earlier README command (its
  ``--out``/``--figure(s)``/``--record``, a bag command's output, a redirection; or below such an output folder).
* ``--help`` examples name the user's own files (``my_loop.yaml``, ``rig.csv``, ...); only their paths into
  ``../shared/data`` and into the repository (src/, docs/, examples/, benchmarks/, scripts/, tests/) are checked.
* Inline README spans may use placeholders in capitals (``FILE``, ``RUN``, ``PRESET``): parsed only.
* ``.venv/bin/python SCRIPT --opt ...`` (benchmarks, examples): the script exists and each ``--opt`` is in its
  source; ``-m pytest PATH``: the path exists; ``bash scripts/X.sh``: the script exists.

Which are also run (in process, ``phfdi.cli.main``, in a temporary folder, exit status 0 required), in the README's
order within each fenced block, and in the epilog's order for ``--help`` examples: every ``phfdi`` command whose
inputs exist or were written by an earlier run command of the same block, except these, which are parsed only:

* ``launch``, ``demo`` and ``replay --live``: they start a ROS 2 graph (this test starts none);
* ``evaluate``, ``analyze``, ``paper-runs``: minutes of simulation;
* ``calibrate`` without ``--learn``/``--estimator``: simulates 16 healthy runs of 10000 s;
* ``diagnose``: 18 s or more each (22 candidate fits);
* ``loop-diagnose`` on a folder, a glob or several files: plant-wide (59 records: 35-70 s on Dask);
* a command reading a file that only a parsed-only command writes (``bag info bags/run.mcap`` after ``launch``).

So run: the README's rig workflow (``calibrate --estimator``, ``replay``, ``inject``, ``replay``), its learned
reference on SKAB (``calibrate --learn``, ``replay --reference``, ``bag from-csv``), ``simulate`` + ``replay``, the
short ``--set`` run, the single-loop ``loop-diagnose``, ``scenarios``, and the cheap ``--help`` examples with real
files (simulate, replay's simulate-then-replay, scenarios, inject, loop-diagnose on one file). Each README block is
run twice in the same folder, as a newcomer following it twice does. And every command the README shows starts
with ``.venv/bin/`` (a newcomer's shell has no ``phfdi`` or project ``python``), and every one that writes gives
``--overwrite`` (the rule of every command: an existing output is kept without it). About 45 s on one core
(2026-12-05); run ``pytest tests/docs -v`` to see each command's verdict in the test ids and skip reasons.
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from phfdi.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
SHARED = "../shared/data"

#: options whose value is a file the command writes
OUTPUT_OPTIONS = {"--out", "--figure", "--figures", "--record", "--predictions"}
#: options whose value is never a file (even when it holds a dot or a slash)
NOT_FILE_OPTIONS = {"--set", "--column", "--unit", "--scheduler", "--group", "--learned", "--calibrate", "--exclude",
                    "--labels", "--signal", "--seeds", "--wavelet", "--fault", "--pump", "--encoding", "--segments"}
#: a token is a file name when it holds a slash or ends like one
FILE_SUFFIXES = (".csv", ".parquet", ".mcap", ".json", ".yaml", ".yml", ".txt", ".png", ".py", ".sh")
#: commands that simulate a scenario with its --fault, --onset and --set (diagnose's --set edits its --model instead)
SCENARIO_COMMANDS = ("simulate", "launch", "demo", "calibrate", "analyze")
#: bag subcommands whose last positional is the file they write
BAG_WRITERS = {"recover", "to-run", "from-csv"}
#: repository folders a --help example may point into (checked); other relative names are the user's own files
REPO_DIRS = ("src/", "docs/", "examples/", "benchmarks/", "scripts/", "tests/")
#: --help examples known broken in a file this change does not own: (exact example, reason); they xfail until fixed
KNOWN_BROKEN: dict[str, str] = {}  # command text -> why it fails today (the test then expects it to fail)


@dataclass
class Command:
    source: str  # where it was written: README.md:LINE, `phfdi X --help`, ...
    text: str  # as written (one line, continuations joined)
    env: dict[str, str]
    program: str  # phfdi, python, bash
    argv: list[str]
    redirect: list[str] = field(default_factory=list)  # files written by > redirections
    inline: bool = False  # an inline README span: placeholders allowed, parsed only


# ---- extraction -------------------------------------------------------------------------------------------
def _join_continuations(lines: list[tuple[int, str]]) -> list[tuple[int, str]]:
    out: list[tuple[int, str]] = []
    pending: tuple[int, str] | None = None
    for number, line in lines:
        if pending is not None:
            number, line = pending[0], pending[1] + " " + line.strip()
        if line.rstrip().endswith("\\"):
            pending = (number, line.rstrip()[:-1].rstrip())
            continue
        pending = None
        out.append((number, line))
    if pending is not None:
        out.append(pending)
    return out


def _split_shell(line: str, variables: dict[str, str]) -> list[tuple[list[str], list[str]]]:
    """(tokens, redirect targets) of each simple command of one shell line."""
    for name, value in variables.items():
        line = line.replace("${" + name + "}", value).replace("$" + name, value)
    lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
    lexer.whitespace_split = True
    commands: list[tuple[list[str], list[str]]] = []
    tokens: list[str] = []
    redirect: list[str] = []
    tokens_iter = iter(list(lexer))
    for token in tokens_iter:
        if token in ("&&", "||", ";", "|", "&"):
            if tokens:
                commands.append((tokens, redirect))
            tokens, redirect = [], []
        elif token in (">", ">>", "2>", "&>"):
            redirect.append(next(tokens_iter))
        else:
            tokens.append(token)
    if tokens:
        commands.append((tokens, redirect))
    return commands


def _command(source: str, text: str, tokens: list[str], redirect: list[str], inline: bool = False) -> Command | None:
    env: dict[str, str] = {}
    while tokens and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", tokens[0]):
        key, _, value = tokens.pop(0).partition("=")
        env[key] = value
    while tokens and tokens[0] in ("nice", "/usr/bin/time", "time"):
        tokens.pop(0)
        while tokens and (tokens[0].startswith("-") or tokens[0].isdigit()):
            tokens.pop(0)
    if not tokens:
        return None
    head = tokens[0]
    if head in ("phfdi", ".venv/bin/phfdi"):
        program = "phfdi"
    elif head in (".venv/bin/python", "python"):
        program = "python"
    elif head == "bash":
        program = "bash"
    else:
        return None
    return Command(source, text, env, program, tokens[1:], redirect, inline)


def readme_blocks() -> list[tuple[str, list[Command]]]:
    """The fenced bash blocks of README.md, each as its list of commands (shell variables carried along)."""
    lines = README.read_text(encoding="utf-8").splitlines()
    blocks: list[tuple[str, list[Command]]] = []
    variables: dict[str, str] = {}
    i = 0
    while i < len(lines):
        if lines[i].strip() == "```bash":
            start = i + 1
            body: list[tuple[int, str]] = []
            i += 1
            while lines[i].strip() != "```":
                body.append((i + 1, lines[i]))
                i += 1
            commands: list[Command] = []
            for number, line in _join_continuations(body):
                assignment = re.fullmatch(r"\s*([A-Z_][A-Z0-9_]*)=(\S+)\s*", line)
                if assignment:
                    variables[assignment.group(1)] = assignment.group(2)
                    continue
                for tokens, redirect in _split_shell(line, variables):
                    cmd = _command(f"README.md:{number}", line.strip(), tokens, redirect)
                    if cmd is not None:
                        commands.append(cmd)
            blocks.append((f"README.md:{start}", commands))
        i += 1
    return blocks


def readme_inline() -> list[Command]:
    """Inline code spans of the README's prose and tables that are commands (fenced blocks left out)."""
    text = re.sub(r"```.*?```", "", README.read_text(encoding="utf-8"), flags=re.S)
    out = []
    for span in re.findall(r"`([^`\n]+)`", text):
        if not re.match(r"(phfdi |\.venv/bin/phfdi |\.venv/bin/python |[A-Z_]+=\S+ \.venv/bin/python )", span):
            continue
        for tokens, redirect in _split_shell(span, {}):
            cmd = _command("README.md (inline)", span, tokens, redirect, inline=True)
            if cmd is not None:
                out.append(cmd)
    return out


def _subparsers(parser: argparse.ArgumentParser, prefix: str = "") -> dict[str, argparse.ArgumentParser]:
    out = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out[f"{prefix}{name}"] = sub
                out.update(_subparsers(sub, f"{prefix}{name} "))
    return out


def help_examples() -> dict[str, list[Command]]:
    """Each top-level subcommand's ``examples:`` lines (bag's subcommands share bag's epilog)."""
    out: dict[str, list[Command]] = {}
    for name, sub in _subparsers(build_parser()).items():
        top = name.split()[0]
        if not sub.epilog or top in out:
            continue
        epilog = sub.epilog.split("examples:", 1)[-1].split("\n\n", 1)[0]
        body = [(k, line) for k, line in enumerate(epilog.splitlines()) if line.strip()]
        commands = []
        for _, line in _join_continuations(body):
            if not line.strip().startswith("phfdi "):
                continue
            for tokens, redirect in _split_shell(line.strip(), {}):
                cmd = _command(f"`phfdi {top} --help`", line.strip(), tokens, redirect)
                if cmd is not None:
                    commands.append(cmd)
        out[top] = commands
    return out


def option_set_examples() -> list[tuple[str, list[str]]]:
    """(where, [KEY=VALUE, ...]) of every ``e.g. --set ...`` in an option's help text."""
    out = []
    for name, sub in _subparsers(build_parser()).items():
        for action in sub._actions:
            if action.dest == "overrides" and action.help and name in SCENARIO_COMMANDS:
                values = re.findall(r"--set (\S+)", action.help)
                if values:
                    out.append((f"`phfdi {name} --help` ({'/'.join(action.option_strings)})", values))
    return out


# ---- reading a parsed command --------------------------------------------------------------------------------
@dataclass
class Parsed:
    subcommand: str  # "simulate", "bag info", ...
    namespace: argparse.Namespace
    inputs: list[str]
    outputs: list[str]


def _leaf(argv: list[str]) -> tuple[str, argparse.ArgumentParser, int]:
    subs = _subparsers(build_parser())
    name, k = "", 0
    while k < len(argv) and f"{name}{argv[k]}".strip() in subs and not argv[k].startswith("-"):
        name = f"{name}{argv[k]} "
        k += 1
    name = name.strip()
    return name, subs.get(name), k


def _is_file(token: str) -> bool:
    return ("/" in token or token.endswith(FILE_SUFFIXES)) and "=" not in token and not token.startswith("-")


def parse(cmd: Command) -> Parsed:
    """Parse with the real parser (a bad subcommand or option fails the test) and tell input from output files."""
    try:
        namespace = build_parser().parse_args(cmd.argv)
    except SystemExit as exc:
        pytest.fail(f"{cmd.source}: `{cmd.text}` does not parse (exit {exc.code})", pytrace=False)
    name, leaf, k = _leaf(cmd.argv)
    assert leaf is not None, f"{cmd.source}: no subcommand in `{cmd.text}`"
    options = leaf._option_string_actions
    inputs, outputs, positionals = [], list(cmd.redirect), []
    rest = cmd.argv[k:]
    j = 0
    while j < len(rest):
        token = rest[j]
        if token.startswith("-") and token.split("=")[0] in options:
            flag = token.split("=")[0]
            action = options[flag]
            if "=" in token:
                values = [token.split("=", 1)[1]]
            elif action.nargs == 0:
                values = []
            elif action.nargs in ("+", "*"):
                values = []
                while j + 1 < len(rest) and not rest[j + 1].startswith("-"):
                    j += 1
                    values.append(rest[j])
            else:
                j += 1
                values = [rest[j]] if j < len(rest) else []
            long_flag = max(action.option_strings, key=len)
            if long_flag in OUTPUT_OPTIONS:
                outputs += values
            elif long_flag not in NOT_FILE_OPTIONS:
                inputs += [v for v in values if _is_file(v)]
        else:
            positionals.append(token)
        j += 1
    if name.startswith("bag ") and name.split()[1] in BAG_WRITERS and positionals:
        outputs.append(positionals.pop())
    inputs += [p for p in positionals if _is_file(p)]
    if name == "demo":
        outputs.append(namespace.out)
    return Parsed(name, namespace, inputs, outputs)


def _placeholder(value: object) -> bool:
    return isinstance(value, str) and bool(re.fullmatch(r"[A-Z][A-Z_.]*", value))


def check_scenario(cmd: Command, parsed: Parsed) -> None:
    """Load the scenario a simulating command would run: its --fault, --onset and --set as the command applies them."""
    from phfdi.scenario import load_scenario

    ns, sub = parsed.namespace, parsed.subcommand
    if sub not in SCENARIO_COMMANDS:
        return
    if sub == "calibrate" and (ns.learn or ns.estimator):
        return
    scenario = getattr(ns, "scenario", None) or "paper"
    if str(scenario).endswith((".yaml", ".yml")) and not Path(scenario).exists():
        return  # the user's own scenario file (a --help example)
    fault, onset = getattr(ns, "fault", None), getattr(ns, "onset", None)
    if sub == "demo":
        fault = fault or "backlash"
    elif sub == "calibrate":
        fault = "healthy"
    elif sub == "analyze":
        fault, onset = "backlash", ns.section7_onset
    if any(_placeholder(v) for v in (scenario, fault)):
        return
    try:
        load_scenario(scenario, fault=fault, overrides=list(ns.overrides), onset_s=onset)
    except Exception as exc:  # noqa: BLE001 - any refusal is the finding
        pytest.fail(f"{cmd.source}: `{cmd.text}`: the scenario refuses it: {exc}", pytrace=False)


def _exists(path: str, base: Path) -> bool:
    full = path if os.path.isabs(path) else str(base / path)
    return bool(glob.glob(full)) if any(c in path for c in "*?[") else os.path.exists(full)


def _written(path: str, written: set[str]) -> bool:
    path = path.rstrip("/")
    return any(path == w.rstrip("/") or path.startswith(w.rstrip("/") + "/") for w in written)


# ---- what each command gets ------------------------------------------------------------------------------------
NEVER_RUN = {
    "launch": "starts a ROS 2 graph",
    "demo": "starts a ROS 2 graph",
    "evaluate": "minutes of simulation",
    "analyze": "minutes of simulation",
    "paper-runs": "minutes of simulation",
    "diagnose": "18 s or more (22 candidate fits)",
}


def why_not_run(parsed: Parsed) -> str | None:
    ns, sub = parsed.namespace, parsed.subcommand
    if sub == "demo" and ns.no_ros:
        return "the whole job without ROS (two 10000 s runs, replays, figures)"
    if sub in NEVER_RUN:
        return NEVER_RUN[sub]
    if sub == "replay" and ns.live:
        return "starts a ROS 2 graph (replay --live)"
    if sub == "calibrate" and not (ns.learn or ns.estimator):
        return "simulates 16 healthy runs of 10000 s"
    if sub == "loop-diagnose" and (len(ns.files) > 1 or any(not p.endswith(FILE_SUFFIXES) or any(c in p for c in "*?[")
                                                            for p in ns.files)):
        return "plant-wide (59 records: 35-70 s on Dask)"
    return None


def check_loop_records(cmd: Command, paths: list[str]) -> None:
    """A plant-wide loop-diagnose that is only parsed still reads each record it would diagnose (about 1 s for the
    59 shared ones): a folder holding a file that is no loop record (labels.csv) fails here."""
    from phfdi.loopdiag.plantwide import expand
    from phfdi.loopdiag.readers import read_loop

    files = [f for p in paths for f in (sorted(glob.glob(p)) if any(c in p for c in "*?[") else [p])]
    for job in expand(files):
        try:
            read_loop(job.path, job.columns)
        except Exception as exc:  # noqa: BLE001 - what the command would report as a failed loop
            pytest.fail(f"{cmd.source}: `{cmd.text}`: {job.path} is not a loop record: {exc}", pytrace=False)


def check_python(cmd: Command) -> None:
    argv = cmd.argv
    if argv[:2] == ["-m", "pytest"]:
        for path in (a for a in argv[2:] if not a.startswith("-")):
            assert (ROOT / path.split("::")[0]).exists(), f"{cmd.source}: `{cmd.text}`: no {path}"
        return
    if argv[0] == "-m":  # a module of the project (a node): it must be there
        import importlib.util

        assert importlib.util.find_spec(argv[1]) is not None, f"{cmd.source}: `{cmd.text}`: no module {argv[1]}"
        return
    script = ROOT / argv[0]
    assert script.is_file(), f"{cmd.source}: `{cmd.text}`: no script {argv[0]}"
    source = script.read_text(encoding="utf-8")
    for option in (a.split("=")[0] for a in argv[1:] if a.startswith("--")):
        assert f'"{option}"' in source or f"'{option}'" in source, \
            f"{cmd.source}: `{cmd.text}`: {argv[0]} has no option {option}"


def check_bash(cmd: Command) -> None:
    assert (ROOT / cmd.argv[0]).is_file(), f"{cmd.source}: `{cmd.text}`: no {cmd.argv[0]}"


def run_sequence(commands: list[Command], shared, readme: bool, run_cli) -> list[str]:
    """Check every command of one block (or one --help) in order, running the cheap ones in the current folder.
    ``shared()`` gives the real data folder (or skips). Returns one verdict line per command (printed, see -s)."""
    verdicts: list[str] = []
    written_all: set[str] = set()  # by any command before (run or parsed)
    written_run: set[str] = set()  # by a command that ran, so present here
    for cmd in commands:
        if cmd.program in ("python", "bash"):
            (check_python if cmd.program == "python" else check_bash)(cmd)
            verdicts.append(f"script checked: {cmd.text}")
            continue
        if cmd.inline and len(cmd.argv) == 1:  # "`phfdi diagnose` drives ...": the command's name in prose
            assert cmd.argv[0] in _subparsers(build_parser()), f"{cmd.source}: no subcommand `{cmd.text}`"
            verdicts.append(f"name checked: {cmd.text}")
            continue
        parsed = parse(cmd)
        check_scenario(cmd, parsed)
        written_all.update(parsed.outputs)
        if cmd.inline:
            verdicts.append(f"parsed (inline, placeholders allowed): {cmd.text}")
            continue
        missing, reason = [], why_not_run(parsed)
        for path in parsed.inputs:
            if path.startswith(SHARED):
                if not _exists(str(shared()) + path[len(SHARED):], ROOT):
                    missing.append(path)
            elif path.startswith(REPO_DIRS) and _exists(path, ROOT):
                pass
            elif _written(path, written_run):
                pass
            elif _written(path, written_all - written_run):
                reason = reason or f"reads {path}, which only a parsed command writes"
            elif readme:
                missing.append(path)  # the README names no file the reader does not have
            else:
                reason = reason or f"reads the user's own file {path}"
        assert not missing, f"{cmd.source}: `{cmd.text}`: no such file: {', '.join(missing)}"
        if reason and parsed.subcommand == "loop-diagnose" and all(p.startswith(SHARED) for p in parsed.inputs):
            check_loop_records(cmd, [str(shared()) + p[len(SHARED):] for p in parsed.inputs])
            reason += "; every record it finds was read"
        if reason:
            verdicts.append(f"parsed only ({reason}): {cmd.text}")
            continue
        argv = []
        for arg in (str(shared()) + a[len(SHARED):] if a.startswith(SHARED) else a for a in cmd.argv):
            argv += sorted(glob.glob(arg)) if any(c in arg for c in "*?[") and "=" not in arg else [arg]
        status, out, err = run_cli(*argv)
        assert status == 0, f"{cmd.source}: `{cmd.text}` exited {status}\n{out[-2000:]}\n{err[-2000:]}"
        for path in cmd.redirect:
            Path(path).write_text(out)
        for path in parsed.outputs:
            assert _exists(path, Path.cwd()), f"{cmd.source}: `{cmd.text}` did not write {path}"
        written_run.update(parsed.outputs)
        verdicts.append(f"ran: {cmd.text}")
    return verdicts


BLOCKS = readme_blocks()
HELP = help_examples()


@pytest.fixture
def shared(request):
    """The real data folder, asked for only by a command that reads it (the shared_data fixture skips when absent)."""
    return lambda: request.getfixturevalue("shared_data")


@pytest.mark.parametrize("block", BLOCKS, ids=[where for where, _ in BLOCKS])
def test_readme_block(block, shared, tmp_path, monkeypatch, run_cli):
    """Each fenced bash block of the README, in order, in a fresh folder: run or parsed and checked; then the
    whole block again in the same folder, as a newcomer who follows the README twice does (a command refusing
    the output of its first run failed there: exit 2)."""
    _, commands = block
    monkeypatch.chdir(tmp_path)
    verdicts = run_sequence(commands, shared, True, run_cli)
    assert run_sequence(commands, shared, True, run_cli) == verdicts
    print("\n".join(verdicts))


#: what a newcomer's shell has after the README's two set-up commands: none of these on its PATH
NOT_ON_PATH = ("phfdi", "python", "python3", "pip", "pytest")


def _typed_commands() -> list[tuple[str, str]]:
    """(where, first word) of every command the README shows: each fenced bash line and inline code span, split at
    ``&&``/``;``/``|``/``&``, environment assignments and ``nice``/``time`` skipped."""
    text = README.read_text(encoding="utf-8")
    lines: list[tuple[str, str]] = []
    for k, body in enumerate(re.findall(r"```bash\n(.*?)```", text, flags=re.S), start=1):
        numbered = list(enumerate(body.splitlines()))
        lines += [(f"README.md, bash block {k}", line) for _, line in _join_continuations(numbered)
                  if line.strip() and not line.lstrip().startswith("#")]
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    lines += [("README.md (inline)", span) for span in re.findall(r"`([^`\n]+)`", prose) if " " in span]
    out = []
    for where, line in lines:
        for tokens, _ in _split_shell(line.split(" #", 1)[0], {}):
            while tokens and (re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", tokens[0]) or tokens[0] in ("nice", "time")):
                tokens.pop(0)
            if tokens:
                out.append((f"{where}: `{line.strip()}`", tokens[0]))
    return out


def test_readme_commands_work_outside_an_activated_venv():
    """The README's bare `phfdi ...` and `python -m ...` failed in a newcomer's shell (command not found, or the
    system Python without the project): every command it shows starts with .venv/bin/ (or bash scripts/...)."""
    typed = _typed_commands()
    assert len(typed) > 40, "the README's commands were not found"
    bare = [where for where, head in typed if head in NOT_ON_PATH]
    assert not bare, "commands a newcomer's shell cannot run:\n" + "\n".join(bare)


#: commands that write a default output folder even without --out
DEFAULT_OUTPUT = {"demo", "diagnose"}


def test_readme_commands_that_write_give_overwrite():
    """Running an example twice exited 2 on the output of the first run: every README command that writes
    (fenced or inline, run here or only parsed: launch, demo, diagnose) gives --overwrite."""
    commands = [c for _, block in BLOCKS for c in block] + readme_inline()
    missing = []
    for cmd in commands:
        if cmd.program != "phfdi" or (cmd.inline and len(cmd.argv) == 1):
            continue
        parsed = parse(cmd)
        if (parsed.outputs or parsed.subcommand in DEFAULT_OUTPUT) and "--overwrite" not in cmd.argv:
            missing.append(f"{cmd.source}: `{cmd.text}`")
    assert not missing, "README commands that write without --overwrite:\n" + "\n".join(missing)


def test_readme_inline_commands(shared, tmp_path, monkeypatch, run_cli):
    """Commands in the README's prose and tables: parsed (placeholders in capitals allowed), scripts checked."""
    commands = readme_inline()
    assert len(commands) >= 20, "the README's inline commands were not found"
    monkeypatch.chdir(tmp_path)
    print("\n".join(run_sequence(commands, shared, True, run_cli)))


@pytest.mark.parametrize("subcommand", sorted(HELP))
def test_help_examples(subcommand, shared, tmp_path, monkeypatch, run_cli):
    """Each subcommand's --help examples, in order, in a fresh folder."""
    commands = HELP[subcommand]
    assert commands, f"phfdi {subcommand} --help has no examples"
    monkeypatch.chdir(tmp_path)
    broken = [c for c in commands if c.text in KNOWN_BROKEN]
    verdicts = run_sequence([c for c in commands if c.text not in KNOWN_BROKEN], shared, False, run_cli)
    print("\n".join(verdicts))
    for cmd in broken:
        try:
            run_sequence([cmd], shared, False, run_cli)
        except (pytest.fail.Exception, AssertionError):
            pytest.xfail(KNOWN_BROKEN[cmd.text])


@pytest.mark.parametrize("where,values", option_set_examples(), ids=lambda v: v if isinstance(v, str) else "")
def test_set_examples_in_option_help(where, values):
    """An option's help that shows ``--set KEY=VALUE`` shows one the paper scenario accepts with every fault preset."""
    from phfdi.faults import preset_names
    from phfdi.scenario import load_scenario

    for fault in preset_names():
        try:
            load_scenario("paper", fault=fault, overrides=values)
        except Exception as exc:  # noqa: BLE001
            pytest.fail(f"{where}: --set {' --set '.join(values)} with --fault {fault}: {exc}", pytrace=False)


def test_what_runs_and_what_is_only_parsed():
    """The run list does not silently shrink: the README's cheap workflows stay run, the long ones parsed."""
    runs, parsed = [], []
    for _, commands in BLOCKS:
        for cmd in commands:
            if cmd.program != "phfdi":
                continue
            p = build_parser().parse_args(cmd.argv)
            name = _leaf(cmd.argv)[0]
            (parsed if why_not_run(Parsed(name, p, [], [])) else runs).append(cmd.text)
    joined = "\n".join(runs)
    for expected in ("calibrate --estimator", "calibrate --learn", "inject ", "--reference rig.json",
                     "--reference ref.json", "bag from-csv", "simulate --fault stiction", "loop-diagnose ../shared"):
        assert expected in joined, f"no README command with {expected!r} is run any more"
    assert any("launch" in t for t in parsed) and any("--live" in t for t in parsed)
