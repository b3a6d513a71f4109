"""Model diagnosis from measured records: what the nominal model gets wrong, which cause explains it, and
the gain (``phfdi diagnose``, docs/diagnosis.md).

:func:`load_record` / :func:`make_record` make the records, :func:`nominal_raw` the nominal model,
:func:`diagnose` (with its :class:`Options`) returns a :class:`Diagnosis` whose report
:func:`verdict_line` and :func:`to_json` print. The public names (``__all__``) are imported from their
modules on first use (:mod:`phfdi_base.lazy`).
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["Diagnosis", "Options", "diagnose", "load_record", "make_record", "nominal_raw", "to_json",
           "verdict_line"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .data import load_record, make_record
    from .model import nominal_raw
    from .pipeline import Diagnosis, Options, diagnose
    from .report import to_json, verdict_line
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
