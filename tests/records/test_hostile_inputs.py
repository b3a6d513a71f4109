"""Hostile inputs of issue 22 answered with one line, never a traceback or a hang: folders and FIFOs where a file
is expected, a link loop, a YAML alias bomb and an oversized YAML, a CSV line past the csv module's 128 KiB."""

from __future__ import annotations

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
