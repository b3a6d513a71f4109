"""The ``phfdi`` command line: one entry point, one module per subcommand.

Each module in :mod:`phfdi.commands` defines ``register(subparsers)`` that
adds its parser and sets ``func`` (called with the parsed arguments, returns
an exit status). A :class:`~phfdi_base.errors.UserError` anywhere becomes one line
on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import sys

from phfdi_base.errors import UserError

from . import __version__

#: subcommand modules, in the order ``phfdi --help`` lists them
COMMANDS = [
    "demo",
    "simulate",
    "scenarios",
    "paper_runs",
    "launch",
    "bag",
    "replay",
    "calibrate",
    "evaluate",
    "analyze",
    "loop_diagnose",
    "diagnose",
    "inject",
    "rig_sim",
]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's convention)
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="phfdi",
        description="Online fault detection for pH control loops: simulate the loop, run it as a ROS 2 "
        "graph, detect and diagnose valve faults.",
    )
    parser.add_argument("--version", action="version", version=f"phfdi {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMANDS:
        importlib.import_module(f"phfdi.commands.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        return _main(argv)
    except KeyboardInterrupt:
        # Ctrl-C before the command runs (building the parser imports for about 0.3 s) or after a command has
        # restored the default handler: one line, the shell's status for SIGINT, no traceback
        print(f"{_prog(argv)}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our output went away (`phfdi replay ... --json | head`): stop quietly, as a Unix tool
        # does on SIGPIPE, and keep the interpreter's final flush of stdout from raising again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a tool ended by a closed pipe
    except Exception as exc:
        if not _caused_by_interrupt(exc):
            raise
        # a Ctrl-C inside an extension module's import comes out as another error (a pybind11 module's "ImportError:
        # initialization failed", seen from scipy in a launch, the KeyboardInterrupt as its context): a Ctrl-C
        print(f"{_prog(argv)}: interrupted", file=sys.stderr)
        return 130


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is in the chain of causes and contexts of ``exc``."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return True
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return False


def _prog(argv: list[str] | None) -> str:
    """``phfdi COMMAND`` as far as the arguments name one (for a line written before they are parsed)."""
    args = sys.argv[1:] if argv is None else argv
    command = next((a for a in args if not a.startswith("-")), None)
    return f"phfdi {command}" if command in {c.replace("_", "-") for c in COMMANDS} else "phfdi"


def _flags(parser: argparse.ArgumentParser, out: dict[str, str] | None = None) -> dict[str, str]:
    """dest -> the option that sets it (its first long form), over every subcommand's parser."""
    out = {} if out is None else out
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _flags(sub, out)
        elif action.option_strings:
            out.setdefault(action.dest, max(action.option_strings, key=lambda o: o.startswith("--")))
    return out


def _refuse_non_finite(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """No option takes inf or NaN: one line naming it, before any work (argparse's float() accepts both)."""
    for name, value in vars(args).items():
        values = value if isinstance(value, (list, tuple)) else [value]
        bad = [v for v in values if isinstance(v, float) and not math.isfinite(v)]
        if bad:
            flag = _flags(parser).get(name, name)
            raise UserError(f"{flag}: must be a finite number, got {bad[0]}")


def _main(argv: list[str] | None) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        _refuse_non_finite(args, parser)
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"phfdi {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"phfdi {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
