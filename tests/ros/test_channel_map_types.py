"""The channel map's table of message types (wavelet_fdi.channel_map.MESSAGE_TYPES, ROS-free) against the real
message classes: every type imports, every field it names exists with a numeric type (a sequence where the
table says array), and the stamp is where the table says."""

from __future__ import annotations

import pytest

from wavelet_fdi.channel_map import MESSAGE_TYPES, STAMP_FIELD, STAMP_HEADER
from wavelet_fdi.map_inputs import message_class

NUMBERS = ("double", "float", "int32", "int64", "uint8", "uint32")


@pytest.mark.parametrize("name", sorted(MESSAGE_TYPES))
def test_each_type_of_the_table_has_the_fields_it_names(name):
    mtype = MESSAGE_TYPES[name]
    fields = message_class(name).get_fields_and_field_types()
    for f in mtype.scalars:
        assert fields[f] in NUMBERS, (name, f, fields[f])
    for f in mtype.arrays:
        assert fields[f].startswith("sequence<") and fields[f][9:-1] in NUMBERS, (name, f, fields[f])
    if mtype.named:
        assert fields[mtype.named[0]] == "sequence<string>" and fields[mtype.named[1]] == "sequence<double>"
    if mtype.stamp == STAMP_HEADER:
        assert fields["header"] == "std_msgs/Header"
    elif mtype.stamp == STAMP_FIELD:
        assert fields["stamp"] == "builtin_interfaces/Time"
    else:
        assert "header" not in fields and "stamp" not in fields
