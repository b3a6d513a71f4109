"""The user's YAML files (scenarios, plant models, column maps): one line naming the file and the problem."""

from __future__ import annotations

import pytest

from phfdi.cli import main
from phfdi_base.errors import UserError
from phfdi_base.yamlfile import read_mapping


@pytest.mark.parametrize("text, message", [
    ("a: [\n", "not valid YAML at line 2"),
    ("- just\n- a list\n", "expected a mapping at the top level"),
    ("", "expected a mapping at the top level"),
])
def test_a_bad_file_is_named_with_its_problem(tmp_path, text, message):
    path = tmp_path / "f.yaml"
    path.write_text(text)
    with pytest.raises(UserError, match=message) as info:
        read_mapping(path)
    assert str(path) in str(info.value)


def test_a_missing_file_is_named_as_what_it_should_have_been(tmp_path):
    with pytest.raises(UserError, match="no such column map: .*none.yaml"):
        read_mapping(tmp_path / "none.yaml", "column map")


@pytest.mark.parametrize("argv", [
    ["loop-diagnose", "DATA", "--columns", "MAP"],
    ["diagnose", "--data", "DATA", "--model", "paper", "--map", "MAP"],
])
def test_commands_refuse_a_broken_column_map_in_one_line(tmp_path, capsys, argv):
    data = tmp_path / "record.csv"
    data.write_text("t,op,pv\n0,1,2\n1,1,2\n")
    bad = tmp_path / "map.yaml"
    bad.write_text("op: [\n")
    argv = [str(data) if a == "DATA" else str(bad) if a == "MAP" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "map.yaml: not valid YAML" in err[0], err


def test_non_utf8_yaml_is_one_line(tmp_path):
    from phfdi_base.errors import UserError
    from phfdi_base.yamlfile import read_mapping

    path = tmp_path / "s.yaml"
    path.write_bytes(b"name: x\n\xff\xfe: 1\n")
    with pytest.raises(UserError, match=r"s.yaml: line 2: not UTF-8 text \(byte 0xff\)"):
        read_mapping(path)


@pytest.mark.parametrize("key, message", [
    ("duration_s.x", "duration_s is float 10000.0, not a mapping"),
    ("setpoints.ph.changes.7.value", "setpoints.ph.changes is a list of 1; '7' is not an index of it"),
    ("setpoints.ph.changes.x", "'x' is not an index of it"),
])
def test_override_through_a_value_that_is_no_mapping(key, message):
    """--set paths through a scalar or past a list's end: one line naming the key (found by the fuzz test)."""
    from phfdi.scenario import load_scenario
    from phfdi_base.errors import UserError

    with pytest.raises(UserError, match=message):
        load_scenario("paper", overrides=[f"{key}=1"])


def test_a_scalar_yaml_cannot_build_is_one_line(tmp_path):
    """PyYAML raises ValueError for a date that does not exist (found by the fuzz test)."""
    from phfdi_base.errors import UserError
    from phfdi_base.yamlfile import read_mapping

    path = tmp_path / "s.yaml"
    path.write_text("name: x\nwhen: 2024-13-45\n")
    with pytest.raises(UserError, match=r"s.yaml: not valid YAML \(a value cannot be read: month must be in 1..12\)"):
        read_mapping(path)
