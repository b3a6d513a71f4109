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
