"""Every command that writes a file writes it one way (phfdi_base.outputs): staged beside the target, synced,
renamed over it. A full disk is one line naming the path and the reason, exit 2, no traceback; the earlier good
file stays; nothing half-written is left; an existing file is kept unless --overwrite, said before any work.

A full disk is made by failing ``os.fsync`` with ENOSPC (the tests run as root, to whom a read-only folder is no
obstacle); a folder that cannot be made by putting a file where the folder should be.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from phfdi.loop import simulate
from phfdi.scenario import load_scenario

SHORT = ["--set", "duration_s=150", "--set", "setpoints.ph.changes=[{at_s: 50, value: 8.0}]"]


@pytest.fixture(scope="module")
def short_files(tmp_path_factory) -> dict[str, Path]:
    """A short run (CSV) and its bag (the recorder's format), made once."""
    from phfdi.bagio import write_run

    folder = tmp_path_factory.mktemp("inputs")
    run = simulate(load_scenario("paper", fault="healthy",  # long enough for a learned reference's bands
                                 overrides=["duration_s=600", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]))
    return {"csv": run.save(folder / "run.csv"), "bag": write_run(run, folder / "run.mcap")}


def _cases(files: dict[str, Path], out: Path) -> dict[str, list[str]]:
    """command -> argv writing ``out`` (a file of the command's kind)."""
    return {
        "simulate": ["simulate", *SHORT, "--out", str(out.with_suffix(".csv"))],
        "simulate-figure": ["simulate", *SHORT, "--figure", str(out.with_suffix(".png"))],
        "calibrate-learn": ["calibrate", "--learn", str(files["csv"]), "--exclude", "fault_severity",
                            "--out", str(out.with_suffix(".json"))],
        "bag-to-run": ["bag", "to-run", str(files["bag"]), str(out.with_suffix(".parquet"))],
        "bag-from-csv": ["bag", "from-csv", str(files["csv"]), str(out.with_suffix(".mcap"))],
        "bag-recover": ["bag", "recover", str(files["bag"]), str(out.with_suffix(".mcap"))],
    }


CASES = ("simulate", "simulate-figure", "calibrate-learn", "bag-to-run", "bag-from-csv", "bag-recover")


def _target(argv: list[str]) -> Path:
    after = {"--out", "--figure"}
    for flag, value in zip(argv, argv[1:]):
        if flag in after:
            return Path(value)
    return Path(argv[-1])


def _one_error_line(err: str) -> str:
    assert "Traceback" not in err, err
    errors = [ln for ln in err.strip().splitlines() if ": error: " in ln]
    assert len(errors) == 1, err
    return errors[0]


@pytest.mark.parametrize("case", CASES)
def test_a_full_disk_keeps_the_earlier_file_and_leaves_nothing_partial(case, short_files, tmp_path, run_cli,
                                                                       monkeypatch):
    argv = _cases(short_files, tmp_path / "out" / "result")[case]
    target = _target(argv)
    status, _, err = run_cli(*argv)
    assert status == 0, err
    good = target.read_bytes()

    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", full_disk)
    status, _, err = run_cli(*argv, "--overwrite")
    assert status == 2
    assert _one_error_line(err).endswith(f"error: cannot write {target}: No space left on device")
    assert target.read_bytes() == good  # the earlier output, byte for byte
    assert sorted(p.name for p in target.parent.iterdir()) == [target.name]  # no staged leftovers


@pytest.mark.parametrize("case", CASES)
def test_an_existing_output_is_kept_without_overwrite(case, short_files, tmp_path, run_cli):
    argv = _cases(short_files, tmp_path / "result")[case]
    target = _target(argv)
    target.write_bytes(b"earlier output")
    status, _, err = run_cli(*argv)
    assert status == 2
    assert _one_error_line(err).endswith(f"{target} exists; give --overwrite to replace it")
    assert target.read_bytes() == b"earlier output"
    status, _, err = run_cli(*argv, "--overwrite")
    assert status == 0, err
    assert target.read_bytes() != b"earlier output"


def test_a_folder_that_cannot_be_made_is_one_line_before_the_work(short_files, tmp_path, run_cli):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the output folder should be")
    for argv in (["diagnose", "--data", str(short_files["csv"]), "--quiet", "--out", str(blocker / "report")],
                 ["loop-diagnose", str(short_files["csv"]), "--no-baselines", "--columns",
                  "op=valve_command_pct,pv=ph_measured,time=time_s", "--out", str(blocker / "loops")],
                 ["simulate", *SHORT, "--out", str(blocker / "run.csv")]):
        status, out, err = run_cli(*argv)
        assert status == 2, (argv, err)
        line = _one_error_line(err)
        assert str(blocker) in line and any(w in line for w in ("Not a directory", "is a file, not a folder",
                                                               "exists")), line
        assert out == ""  # nothing computed and reported first


def test_outputs_get_the_usual_permissions(short_files, tmp_path, run_cli):
    """Staged files are created private (mkstemp's 0600); the output gets what the umask gives a new file."""
    target = tmp_path / "run.csv"
    status, _, err = run_cli("simulate", *SHORT, "--out", str(target))
    assert status == 0, err
    mask = os.umask(0)
    os.umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask


#: the commands that write a folder (--out DIR): argv without --out, and whether the test runs it with
#: --overwrite too (the others take minutes; their refusal is what is checked)
FOLDER_COMMANDS = {
    "demo": (["demo", "--no-ros", "--onset", "1000", "--set", "duration_s=1600",
              "--set", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"], True),
    "diagnose": (["diagnose", "--data", "{csv}", "--model", "paper", "--candidates", "sensor_bias", "--no-pairs",
                  "--workers", "1", "--quiet"], True),
    "loop-diagnose": (["loop-diagnose", "{csv}", "--no-baselines", "--causes", "stiction", "--columns",
                       "op=valve_command_pct,pv=ph_measured,time=time_s"], True),
    "evaluate": (["evaluate", "--quick"], False),
    "analyze": (["analyze"], False),
    "paper-runs": (["paper-runs"], False),
}


@pytest.mark.parametrize("command", FOLDER_COMMANDS)
def test_an_output_folder_of_an_earlier_run_is_kept_without_overwrite(command, short_files, tmp_path, run_cli):
    """One rule for every command that writes: `demo` and `diagnose --out` silently replaced an earlier run's
    files where `simulate --out` refused. A folder that holds files is now written into only with --overwrite,
    refused before any work (nothing printed, the earlier file untouched)."""
    argv, runs = FOLDER_COMMANDS[command]
    argv = [a.replace("{csv}", str(short_files["csv"])) for a in argv]
    out = tmp_path / "out"
    out.mkdir()
    earlier = out / "REPORT.md"
    earlier.write_text("an earlier run's report\n")
    status, printed, err = run_cli(*argv, "--out", str(out))
    assert status == 2 and printed == "", err
    assert _one_error_line(err).endswith(f"{out} holds files of an earlier run; give --overwrite to replace them "
                                         f"(or another folder)")
    assert earlier.read_text() == "an earlier run's report\n"
    if runs:
        status, _, err = run_cli(*argv, "--out", str(out), "--overwrite")
        assert status == 0, err
        assert len(list(out.iterdir())) > 1  # its own files beside the one it does not write


def test_without_hard_links_a_new_file_is_still_created_exclusively(tmp_path, monkeypatch):
    """On a file system without hard links (FAT, some network mounts) the name is reserved by O_EXCL instead."""
    import errno

    from phfdi_base.outputs import OutputError, write_text

    def no_links(src, dst):
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_links)
    target = tmp_path / "run.csv"
    write_text(target, "first\n")
    with pytest.raises(OutputError, match="run.csv exists; give --overwrite"):
        write_text(target, "second\n")
    write_text(target, "third\n", overwrite=True)
    assert target.read_text() == "third\n" and [p.name for p in tmp_path.iterdir()] == ["run.csv"]
