"""Arguments and output helpers shared by subcommands."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from contextlib import contextmanager

FAULT_PRESETS = "{fault_presets}"
#: in an epilog: the diagnosis's candidates from catalogued faults of one's own blocks (a line, or nothing)
OWN_CANDIDATES = "{own_candidates}\n"


class EpilogFormat(argparse.RawDescriptionHelpFormatter):
    """Examples kept as written; ``{fault_presets}`` in an option's help becomes the catalogue's presets,
    read only when help is printed (importing the cores costs a third of a second)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = super()._get_help_string(action) or ""
        if FAULT_PRESETS in text:
            from phfdi.faults import preset_names

            text = text.replace(FAULT_PRESETS, ", ".join(preset_names()))
        return text

    def _format_text(self, text: str) -> str:
        if OWN_CANDIDATES in text:
            from phfdi.diagnosis.report import CAUSES, causes

            own = [f"{c} ({family})" for c, family in causes().items() if c not in CAUSES]
            text = text.replace(OWN_CANDIDATES, f"  Your blocks' faults (fault catalogue): {' '.join(own)}.\n" if own else "")
        return super()._format_text(text)


EPILOG_FORMAT = EpilogFormat


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", default="paper", help="scenario preset name or a .yaml file (default: paper)")
    p.add_argument("--fault", default=None,
                   help=f"fault from the library replacing the scenario's faults ({FAULT_PRESETS})")
    p.add_argument("--onset", type=float, default=None, metavar="S", help="fault onset time (s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key, e.g. --set sensors.ph.noise_std=0.02 --set duration_s=12000")


def scenario_from_args(args: argparse.Namespace):
    from phfdi.scenario import load_scenario

    return load_scenario(args.scenario, fault=args.fault, overrides=args.overrides, onset_s=args.onset)


class Progress:
    """One line of progress on stderr for long work (silent when not a terminal unless forced)."""

    def __init__(self, label: str, enabled: bool | None = None) -> None:
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()

    def __call__(self, fraction: float) -> None:
        if self.enabled:
            end = "\n" if fraction >= 1.0 else ""
            print(f"\r{self.label}: {100 * fraction:5.1f} %  ({time.perf_counter() - self.t0:5.1f} s)",
                  end=end, file=sys.stderr, flush=True)


# ---- measured records (phfdi.records) -------------------------------------------------------
def add_overwrite_arg(p: argparse.ArgumentParser, folder: bool = False) -> None:
    """--overwrite: without it an existing output file (or an output folder that holds files) is kept and the
    command stops with one line, before any work (outputs are written atomically either way: docs/records.md,
    "Writing files"). The one rule of every command that writes."""
    what = "write into an output folder that holds files, replacing the files this command writes there" \
        if folder else "replace an existing output file"
    p.add_argument("--overwrite", action="store_true", help=f"{what} (default: refuse, before any work)")


def add_record_args(p: argparse.ArgumentParser, units: bool = True) -> None:
    """--map, --column, --unit and --encoding: how to read a user's record (see docs/records.md)."""
    g = p.add_argument_group("reading the file")
    g.add_argument("--map", default=None, metavar="FILE",
                   help="column map: a YAML file (signal: column, or signal: {column:, unit:}) or a shipped "
                        "name (ph_rig)")
    g.add_argument("--column", action="append", default=[], metavar="SIGNAL=COLUMN",
                   help="map one column, e.g. --column ph_measured=pH (instead of --map)")
    if units:
        g.add_argument("--unit", action="append", default=[], metavar="SIGNAL=UNIT",
                       help="unit of a --column, e.g. --unit time_s=min")
    g.add_argument("--encoding", default=None,
                   help="text encoding of a CSV when it cannot be detected (e.g. cp1250, shift_jis)")


def shipped_map(name: str):
    """The path of a column map shipped with phfdi (phfdi/diagnosis/maps/NAME.yaml), or None."""
    from importlib import resources
    from pathlib import Path

    path = Path(str(resources.files("phfdi.diagnosis"))) / "maps" / f"{name}.yaml"
    return path if path.exists() else None


def column_map_from_args(args: argparse.Namespace):
    """The :class:`phfdi.records.ColumnMap` of --map or --column/--unit; None when neither is given."""
    from phfdi.records import ColumnMap
    from phfdi_base.errors import UserError

    units = getattr(args, "unit", [])
    if args.map and args.column:
        raise UserError("give either --map or --column, not both")
    if args.map:
        if not args.map.endswith((".yaml", ".yml")):
            path = shipped_map(args.map)
            if path is None:
                raise UserError(f"--map {args.map!r}: not a .yaml file nor a shipped map (ph_rig)")
            return ColumnMap.load(path)
        return ColumnMap.load(args.map)
    if args.column:
        return ColumnMap.from_args(args.column, units)
    if units:
        raise UserError("--unit goes with --column")
    return None


def map_given_as(args: argparse.Namespace) -> str | None:
    """How the command line named the columns (``--map ph_rig``, ``--column a=b --unit a=min``), or None."""
    if args.map:
        return f"--map {args.map}"
    if args.column:  # quoted as a shell would need it (historian tags have spaces)
        return " ".join([*(f"--column {shlex.quote(c)}" for c in args.column),
                         *(f"--unit {shlex.quote(u)}" for u in getattr(args, "unit", []))])
    return None


def store_column_map(args: argparse.Namespace, model) -> None:
    """Keep the calibration's column map in the reference file (``source``), so that ``phfdi replay
    --reference`` reads new exports of the same historian without the map given again."""
    cmap = column_map_from_args(args)
    if cmap is not None:
        model.source["column_map"] = cmap.to_mapping()
        model.source["column_map_given_as"] = map_given_as(args)


def reference_column_map(args: argparse.Namespace, model, reference: str) -> tuple[object, str]:
    """The column map a replay with a reference reads the record with, and a line saying which one: an explicit
    --map/--column wins over the map stored in the reference; neither: every column under its own name."""
    from phfdi.records import ColumnMap
    from phfdi.records.formats import is_format

    given = column_map_from_args(args)
    stored = model.source.get("column_map")
    if given is not None:
        also = f" (not the map stored in {reference})" if stored else ""
        return given, f"columns: {map_given_as(args)} as given{also}"
    if stored and is_format(args.file, "bag"):  # a bag holds the channels under the project's names already
        return None, "columns: the bag's own channel names"
    if stored:
        how = model.source.get("column_map_given_as") or "a column map"
        return (ColumnMap.from_mapping(stored, f"{reference}: stored column map"),
                f"columns: the map stored in {reference} (calibrated with {how})")
    return None, "columns: the file's own column names"


def print_notes(command: str, notes: list[str]) -> None:
    """Every repair the reader made, one line each on stderr."""
    for note in notes:
        print(f"phfdi {command}: note: {note}", file=sys.stderr)


@contextmanager
def plant_runs_on(source: str):
    """The plant core refuses inputs it cannot integrate (no steady state, flows beyond its sub-step bound)
    with a ValueError; for a user's record that is one line naming the record, not a traceback."""
    from phfdi_base.errors import UserError

    try:
        yield
    except ValueError as exc:
        raise UserError(f"{source}: the plant model cannot run on this record's inputs ({exc})") from None
