"""One reader for measured records, used by every command that takes a file.

:func:`read_record` reads CSV (any delimiter; UTF-8, UTF-8 with BOM, UTF-16, latin-1/cp1252 detected,
anything else named in the error), Parquet and MCAP bags of the node graph into a :class:`Record`:
samples in the project's names and units, NaN where missing, and a note for every repair (naming
file, line and column). What cannot be repaired raises :class:`ReadError`, a
:class:`~phfdi_base.errors.UserError` with one line ``FILE: line N, column 'X': problem``. The policy
table is in :mod:`phfdi.records.policy` and docs/records.md.

Examples
--------
>>> from phfdi.records import POLICIES
>>> POLICIES  # read_record's policy: a run refuses a clock reset, a historian export starts a new segment
('run', 'historian')
"""

from .columns import ColumnMap, ColumnSpec, ModeSpec, QualitySpec
from .errors import ReadError
from .policy import POLICIES
from .reader import read_record, read_run, record_from_table
from .record import Record

__all__ = ["ColumnMap", "ColumnSpec", "ModeSpec", "QualitySpec", "POLICIES", "ReadError", "Record", "read_record", "read_run",
           "record_from_table"]
