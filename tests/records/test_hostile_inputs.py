"""Hostile inputs of issue 22 answered with one line, never a traceback or a hang: folders and FIFOs where a file
is expected, a link loop, a YAML alias bomb and an oversized YAML, a CSV line past the csv module's 128 KiB."""

from __future__ import annotations

import json
import os

import pytest


def _one_line(status: int, err: str) -> str:
    assert status == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "pipe.mcap"
    os.mkfifo(path)  # opening it for reading would wait for a writer forever
    return path


@pytest.mark.parametrize("argv", [["bag", "info", "{p}"], ["bag", "recover", "{p}", "{out}"], ["replay", "{p}"],
                                  ["bag", "to-run", "{p}", "{out}.csv"]])
def test_a_fifo_is_refused_without_reading_it(argv, fifo, tmp_path, run_cli):
    args = [a.format(p=fifo, out=tmp_path / "o") for a in argv]
    line = _one_line(*run_cli(*args)[::2])
    assert str(fifo) in line and "FIFO" in line, line


def test_a_folder_and_a_link_loop_are_one_line(tmp_path, run_cli):
    folder = tmp_path / "bags"
    folder.mkdir()
    assert "a folder" in _one_line(*run_cli("bag", "info", str(folder))[::2])
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.symlink_to(b)
    b.symlink_to(a)
    assert "symbolic links" in _one_line(*run_cli("replay", str(a))[::2])


def test_a_yaml_alias_bomb_is_refused_before_it_expands(tmp_path, run_cli):
    rows = ['a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]']
    rows += [f"{n}: &{n} [{', '.join([f'*{p}'] * 9)}]" for p, n in zip("abcdefgh", "bcdefghi")]
    bomb = tmp_path / "scenario.yaml"
    bomb.write_text("\n".join(rows) + "\n")  # 9^9 = 387 million strings once expanded
    assert "aliases" in _one_line(*run_cli("simulate", "--scenario", str(bomb))[::2])
    big = tmp_path / "big.yaml"
    big.write_text("name: x\n" + "# padding\n" * 120_000)
    assert "larger than 1 MiB" in _one_line(*run_cli("simulate", "--scenario", str(big))[::2])


def test_a_csv_line_past_128_kib_is_read(tmp_path, run_cli):
    """A wide historian header (thousands of tags) runs past the csv module's default field limit."""
    wide = tmp_path / "wide.csv"
    wide.write_text("time_s,ph_measured,valve_command_pct,comment\n"
                    + "".join(f"{k},7.0,50,{'x' * (200_000 if k == 0 else 1)}\n" for k in range(50)))
    status, out, err = run_cli("replay", str(wide), "--no-isolation")
    assert "Traceback" not in err and "field limit" not in err
    long_name = tmp_path / "long_name.csv"
    long_name.write_text("y" * 200_000 + ",time_s\n0,1\n")
    line = _one_line(*run_cli("replay", str(long_name))[::2])
    assert len(line) < 500 and "(200000 chars)" in line


@pytest.mark.parametrize("first, step, what", [(1.7e12, 1000.0, "epoch milliseconds"),
                                               (1.7e15, 1e6, "epoch microseconds"),
                                               (45000.5, 1 / 86400, "spreadsheet serial days"),
                                               (0.0, 1.0, None), (1.7e9, 1.0, None)])
def test_time_columns_in_other_units_are_told_by_their_range_and_said(first, step, what, tmp_path):
    """A backlash run stamped in epoch milliseconds was read as seconds without a word (1000 s per sample)."""
    import numpy as np

    from phfdi.records import read_run

    path = tmp_path / "stamps.csv"
    path.write_text("time,ph_measured,valve_command_pct\n"
                    + "".join(f"{first + k * step!r},{7 + 0.1 * (k % 3)},50\n" for k in range(100)))
    run = read_run(path)
    assert np.allclose(np.diff(run.time_s), 1.0, atol=1e-4)  # one second per sample, whatever the unit
    said = [n for n in run.metadata["notes"] if "column 'time'" in n]
    assert (said == []) if what is None else (len(said) == 1 and what in said[0]), said


def _bag_with_no_samples(path):
    from phfdi import bagio
    from phfdi_base import topics as T

    bag = bagio.BagWriter(path)
    for topic in T.RECORDED:
        if topic.per_sample:
            bag.add_topic(topic.name, topic.type)
    bag.close()
    return path


def test_live_replay_refuses_what_offline_replay_refuses(tmp_path, run_cli):
    """--live played a bag with no sample as "played 0 samples", exit 0, where offline replay refuses it; the
    refusal comes from the offline reader before any process starts (same line both ways)."""
    bag = _bag_with_no_samples(tmp_path / "empty.mcap")
    offline = _one_line(*run_cli("replay", str(bag))[::2])
    live = _one_line(*run_cli("replay", "--live", str(bag))[::2])
    assert "no sample of /plant/measurement" in offline
    assert live.replace("replay", "") == offline.replace("replay", "")


def test_a_bag_with_repeated_stamps_keeps_the_first_and_says_so(tmp_path):
    """Two runs recorded into one bag (or a stray publisher): the last message of a stamp silently replaced the
    first. Now the first is kept (as the graph's lock-step nodes take it) and the repeats are counted in a note."""
    import numpy as np

    from phfdi import bagio
    from phfdi.records import read_run
    from phfdi.records.record import Record
    t = np.arange(20.0)
    first = Record.of({"time_s": t, "ph_measured": np.full(20, 7.0)}, {"sample_time_s": 1.0})
    second = Record.of({"time_s": t[:5], "ph_measured": np.full(5, 9.0)}, {"sample_time_s": 1.0})
    a, b = bagio.write_run(first, tmp_path / "a.mcap"), bagio.write_run(second, tmp_path / "b.mcap")
    both = tmp_path / "both.mcap"
    _merge_bags([a, b], both)
    run = read_run(both)
    assert len(run) == 20 and np.all(run["ph_measured"] == 7.0)
    (note,) = [n for n in run.metadata["notes"] if "repeat a stamp" in n]
    assert "/plant/measurement 5" in note, note


def _merge_bags(parts, out) -> None:
    """One bag holding every message of ``parts`` (their channels and schemas from the first), in file order."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(out, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        ids: dict[str, int] = {}
        for part in parts:
            with open(part, "rb") as src:
                reader = make_reader(src)
                if not ids:
                    for rec in reader.iter_metadata():
                        w.add_metadata(rec.name, rec.metadata)
                for schema, channel, message in reader.iter_messages():
                    if channel.topic not in ids:
                        sid = w.register_schema(schema.name, schema.encoding, schema.data)
                        ids[channel.topic] = w.register_channel(channel.topic, channel.message_encoding, sid,
                                                                channel.metadata)
                    w.add_message(ids[channel.topic], message.log_time, message.data, message.publish_time)
        w.finish()


@pytest.mark.parametrize("head", [b"", b"time_s,ph_measured,valve_command_pct\n0,7.0,50\n1,7.0,50\n"],
                         ids=["all_nul", "header_then_nul"])
@pytest.mark.parametrize("name", ["sparse.csv", "sparse.mcap", "sparse.parquet", "sparse.txt"])
def test_a_sparse_file_is_refused_before_it_is_read(head, name, tmp_path):
    """A sparse file (``truncate -s 2G``: all NUL bytes, valid UTF-8, one endless line) was read and decoded whole:
    2 GB cost 15 GB before the csv module refused it. Now a sample of blocks refuses it; Python's allocations
    while reading a 64 MiB one stay under 1 MiB (before: over 64 MiB, the file itself)."""
    import tracemalloc

    from phfdi.records import ReadError, read_record

    path = tmp_path / name
    path.write_bytes(head)
    os.truncate(path, 64 << 20)  # a hole: no disk used
    tracemalloc.start()
    try:
        with pytest.raises(ReadError, match="NUL") as info:
            read_record(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert str(path) in str(info.value) and "sparse or zero-filled file (64.0 MiB)" in str(info.value)
    assert peak < 1 << 20, f"{peak / 2**20:.1f} MiB allocated to refuse it"


def test_a_sparse_file_is_one_line_from_the_commands(tmp_path, run_cli):
    path = tmp_path / "sparse.csv"
    path.write_bytes(b"")
    os.truncate(path, 64 << 20)  # (2 GiB measured by hand: 0.5 s, 56 MB peak RSS; it cost 15 GB before)
    for argv in (["replay", str(path)], ["bag", "from-csv", str(path), str(tmp_path / "x.mcap")],
                 ["loop-diagnose", str(path)], ["bag", "info", str(path)]):
        line = _one_line(*run_cli(*argv)[::2])
        assert str(path) in line and ("NUL" in line or "not an MCAP file" in line), line


def test_a_short_nul_tail_is_left_to_the_reader(tmp_path):
    """A logger that died mid-write leaves a few NUL bytes at the end: not refused as a sparse file."""
    from phfdi.records import read_record

    path = tmp_path / "died.csv"
    path.write_bytes(b"time_s,ph_measured\n" + b"".join(b"%d,7.0\n" % k for k in range(5000)) + b"\0" * 300)
    record = read_record(path)
    assert len(record.time_s) >= 5000


def _twice(text: str, key_line: str) -> str:
    """``text`` with ``key_line`` (a line of it) repeated right after itself."""
    assert key_line in text.splitlines(), key_line
    return text.replace(key_line + "\n", key_line + "\n" + key_line + "\n", 1)


def _shipped(relative: str) -> str:
    from tests.conftest import ROOT

    return (ROOT / relative).read_text(encoding="utf-8")


@pytest.mark.parametrize("what", ["column map", "scenario", "plant model", "loop column map", "--set"])
def test_a_duplicate_yaml_key_is_refused_naming_it(what, tmp_path, run_cli):
    """YAML keeps the last of two equal keys without a word: a column map naming ph_measured twice, a scenario
    with duration_s twice, used one of them silently. Each is now one line naming the file, the key and the line."""
    record = tmp_path / "loop.csv"
    record.write_text("t,pH,op,pv,sp\n" + "".join(f"{k},7.0,50,1,1\n" for k in range(200)))
    path = tmp_path / "file.yaml"
    if what == "column map":
        path.write_text("time_s: t\nph_measured: pH\nph_measured: op\n")
        argv, key, line = ["replay", str(record), "--map", str(path)], "ph_measured", 3
    elif what == "scenario":
        path.write_text(_twice(_shipped("src/phfdi/scenarios/paper.yaml"), "duration_s: 10000.0"))
        argv, key = ["simulate", "--scenario", str(path), "--out", str(tmp_path / "r.csv")], "duration_s"
        line = next(k for k, t in enumerate(path.read_text().splitlines(), 1) if t == "duration_s: 10000.0") + 1
    elif what == "plant model":
        text = _shipped("src/ph_plant_sim/presets/paper.yaml")
        first = next(t for t in text.splitlines() if t and not t.startswith((" ", "#")) and ":" in t)
        path.write_text(_twice(text, first))
        scenario = tmp_path / "s.yaml"
        scenario.write_text(_shipped("src/phfdi/scenarios/paper.yaml").replace("plant: paper", f"plant: {path}"))
        argv, key = ["simulate", "--scenario", str(scenario), "--out", str(tmp_path / "r.csv")], first.split(":")[0]
        line = text.splitlines().index(first) + 2
    elif what == "loop column map":
        path.write_text("columns: {time: t, op: op, pv: pv, sp: sp}\ncolumns: {time: t, op: pv, pv: op}\n")
        argv, key, line = ["loop-diagnose", str(record), "--columns", str(path)], "columns", 2
    else:
        argv = ["simulate", "--set", "sensors.ph={bias: 0.1, bias: 0.2}", "--out", str(tmp_path / "r.csv")]
        key, line, path = "bias", 1, "--set sensors.ph"
    status, _, err = run_cli(*argv)
    message = _one_line(status, err)
    assert f"{path}: line {line}: key {key!r} appears twice" in message, message


def test_a_channel_map_with_a_channel_twice_is_refused(tmp_path):
    from phfdi_base.errors import UserError
    from wavelet_fdi.channel_map import load_channel_map

    text = _shipped("config/channel_map_skab.yaml")
    line = next(t for t in text.splitlines() if t.strip().startswith("Current:"))
    path = tmp_path / "channels.yaml"
    path.write_text(_twice(text, line))
    with pytest.raises(UserError, match=r"channels.yaml: line \d+: key 'Current' appears twice"):
        load_channel_map(path)


#: the first and last stamps of :func:`_rig_csv`: float noise as the rig's own (1.25200000000041), either side
FIRST_STAMP, LAST_STAMP = "1.25200000000041", "140.90199999999"


def _rig_csv(path, n: int = 400):
    """A record in the rig's columns, 0.35 s apart, from FIRST_STAMP to LAST_STAMP."""
    header = 'Time, ElapsedTime (s),"%, Acid","%, Base","Acid Flow, mL/s","Base Flow, mL/s","pH","T_Room",,,,\n'
    stamps = [FIRST_STAMP, *(f"{1.252 + 0.35 * k:.3f}" for k in range(1, n - 1)), LAST_STAMP]
    rows = [f"2/24/2025 2:00:00 PM , {stamps[k]} ,60.00,"
            f"{100 if (k // 40) % 2 == 0 else 0:.2f},4.31,{6.45 if (k // 40) % 2 == 0 else 0:.2f},"
            f"{7 + (k % 7) / 10:.2f},22.5,,,,\n" for k in range(n)]
    path.write_text(header + "".join(rows))
    return path


@pytest.mark.parametrize("kind, size, says", [
    ("probe_bias", "1e308", "from -14 to 14 pH"), ("probe_bias", "-14.5", "from -14 to 14 pH"),
    ("probe_drift", "1e308", "from -14 to 14 pH/min"), ("probe_noise", "1e308", "above 0 and at most 14 pH (std)"),
    ("probe_noise", "0", "above 0 and at most 14 pH (std)"), ("probe_lag", "1e308", "above 0 and at most 86400 s"),
    ("probe_gain", "1e308", "above -1 and at most 10 (a fraction)"),
    ("probe_gain", "-1", "above -1 and at most 10 (a fraction)"),
    ("pump_low", "1", "above 0 and below 1 (a fraction)"),
    ("pump_high", "1e308", "above 0 and at most 10 (a fraction)"),
    ("pump_stuck", "1e308", "above 0 and at most 1000 mL/s")])
def test_an_inject_size_outside_its_kinds_range_is_one_line(kind, size, says, tmp_path, run_cli):
    """--size 1e308 was taken with numpy overflow warnings and wrote a flow cell of 309 digits beside a command
    left unchanged; each kind now has its range (phfdi.inject_kinds.KINDS), refused naming kind, range and unit."""
    record = _rig_csv(tmp_path / "rig.csv")
    pump = ["--pump", "base"] if kind.startswith("pump_") else []
    out = tmp_path / "faulty.csv"
    status, _, err = run_cli("inject", str(record), "--fault", kind, "--size", size, "--onset", "20", *pump,
                             "--out", str(out))
    line = _one_line(status, err)
    assert f"--size {float(size):g}: {kind} takes a size {says}" in line, line
    assert "Warning" not in err and not out.exists()


def test_an_onset_at_the_first_stamp_as_shown_is_taken(tmp_path, run_cli):
    """The rig's first stamp 1.25200000000041 s was shown as 1.252 s in the refusal of --onset 1.252 ("outside
    the record: its time runs from 1.252 ..."). An onset a float rounding off the first or last stamp is now that
    stamp; one really outside is refused naming the exact stamps."""
    record = _rig_csv(tmp_path / "rig.csv")
    for onset, row in (("1.252", 0), ("140.902", 399)):  # each stamp as :g shows it
        out = tmp_path / f"at_{row}.csv"
        status, text, err = run_cli("inject", str(record), "--fault", "probe_bias", "--size", "1", "--onset", onset,
                                    "--out", str(out), "--json")
        assert status == 0, err
        truth = json.loads(text)
        assert truth["onset_index"] == row and truth["onset_line"] == row + 2, truth
    line = _one_line(*run_cli("inject", str(record), "--fault", "probe_bias", "--size", "1", "--onset", "1.25",
                              "--out", str(tmp_path / "before.csv"))[::2])
    assert f"--onset 1.25 s is outside the record: its time ('ElapsedTime (s)') runs from {FIRST_STAMP} to " \
           f"{LAST_STAMP} s" in line, line


#: a driver of one `phfdi` process in a race: every "exists?" check (phfdi_base.outputs.refuse_existing) waits at
#: a barrier until the other process has made the same check, so both pass every check before either writes (the
#: interleaving a real race needs); placing a .fault.json it waits BEFORE_S before and AFTER_S after (a slow disk)
RACER = """
import os, sys, time
from pathlib import Path
import phfdi_base.outputs as outputs
me, other, folder = sys.argv[1], sys.argv[2], Path(sys.argv[3])
before_s, after_s = (float(x) for x in sys.argv[4].split(":"))
check, calls = outputs.refuse_existing, [0]
def at_barrier(path, overwrite):
    check(path, overwrite)
    calls[0] += 1
    (folder / f"{me}.{calls[0]}").touch()
    deadline = time.monotonic() + 60
    while not (folder / f"{other}.{calls[0]}").exists() and time.monotonic() < deadline:
        time.sleep(0.002)
outputs.refuse_existing = at_barrier
def slowly(place):
    def placed(src, dst, *a, **k):
        truth = str(dst).endswith(".fault.json")
        time.sleep(before_s if truth else 0.0)
        place(src, dst, *a, **k)
        time.sleep(after_s if truth else 0.0)
    return placed
os.replace, os.link = slowly(os.replace), slowly(os.link)
from phfdi.cli import main
sys.exit(main(sys.argv[5:]))
"""


def _race(tmp_path, argv_a: list[str], argv_b: list[str], slow: tuple[str, str] = ("0:0", "0:0")):
    """Run two `phfdi` processes at once under :data:`RACER`: [(status, stderr)] of each."""
    import subprocess
    import sys

    driver = tmp_path / "racer.py"
    driver.write_text(RACER)
    barrier = tmp_path / "barrier"
    barrier.mkdir()
    procs = [subprocess.Popen([sys.executable, str(driver), me, other, str(barrier), wait, *argv],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for me, other, wait, argv in (("a", "b", slow[0], argv_a), ("b", "a", slow[1], argv_b))]
    return [(p.wait(timeout=120), p.communicate()[1]) for p in procs]


@pytest.mark.parametrize("command", ["inject", "bag from-csv"])
def test_two_commands_writing_one_new_file_at_once_cannot_both_succeed(command, tmp_path):
    """Both passed the "exists?" check, then both renamed into place: two `inject --out X` (or `bag from-csv ..
    X`) at once both exited 0, the second silently replacing the first. Now a new file is created exclusively
    (a hard link of the staged file): one wins, the other is one line, and no staged file is left."""
    record = _rig_csv(tmp_path / "rig.csv")
    if command == "inject":
        out = tmp_path / "faulty.csv"
        argv = [["inject", str(record), "--fault", "probe_bias", "--size", size, "--onset", "20", "--out", str(out)]
                for size in ("0.5", "1")]
    else:
        out = tmp_path / "rig.mcap"
        argv = [["bag", "from-csv", str(record), str(out), "--map", "ph_rig"]] * 2
    results = _race(tmp_path, *argv)
    statuses = sorted(status for status, _ in results)
    assert statuses == [0, 2], results
    loser = next(err for status, err in results if status == 2)
    line = _one_line(2, loser)  # inject places the truth first: that is the file it finds
    assert f"error: {out}" in line and line.endswith(" exists; give --overwrite to replace it"), line
    assert not [p for p in tmp_path.iterdir() if ".partial" in p.name]
    if command == "inject":
        from phfdi.inject import read_truth

        assert read_truth(out)["kind"] == "probe_bias"  # the winner's pair: the truth's hash is its CSV's


def test_two_overwriting_injects_at_once_leave_one_runs_pair(tmp_path):
    """With --overwrite, two injects of one name at once could leave the CSV of one and the .fault.json of the
    other (truth a, truth b, CSV b, CSV a). The pair is now placed under its folder's lock: whichever runs last,
    its CSV and its truth stand together (the truth's size is the CSV's, and its sha256 matches)."""
    import numpy as np

    from phfdi.inject import read_truth
    from phfdi.records import read_record

    record = _rig_csv(tmp_path / "rig.csv")
    out = tmp_path / "faulty.csv"
    argv = [["inject", str(record), "--fault", "probe_bias", "--size", size, "--onset", "20", "--out", str(out),
             "--overwrite"] for size in ("0.5", "1")]
    # unlocked, this is truth a (0 s), truth b (0.2 s), CSV b (0.25 s), CSV a (0.8 s): a's CSV with b's truth
    results = _race(tmp_path, *argv, slow=("0:0.8", "0.2:0.05"))
    assert [status for status, _ in results] == [0, 0], results
    truth = json.loads((tmp_path / "faulty.csv.fault.json").read_text())
    cmap = {"time_s": "ElapsedTime (s)", "ph_measured": "pH"}
    shift = read_record(out, cmap).signals["ph_measured"] - read_record(record, cmap).signals["ph_measured"]
    assert np.isclose(np.nanmax(shift), truth["size"]), (np.nanmax(shift), truth["size"])
    assert read_truth(out) == truth
