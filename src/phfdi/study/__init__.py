"""The paper's offline study and the detector's evaluation, composed from the cores.

:mod:`~phfdi.study.paperset` simulates the paper's data sets, :mod:`~phfdi.study.evaluation` runs the
detector and its peers over the scenario matrix, :mod:`~phfdi.study.detector_figures` draws the results.

The offline multisignal wavelet analysis of the paper's Sections 6 and 7 (``phfdi analyze``,
docs/analysis.md): :mod:`~phfdi.study.multisignal` (the data and its row decomposition),
:mod:`~phfdi.study.denoise`, :mod:`~phfdi.study.compress`, :mod:`~phfdi.study.cluster`,
:mod:`~phfdi.study.changepoint`, :mod:`~phfdi.study.residuals`, all run by :mod:`~phfdi.study.analysis`;
:mod:`~phfdi.study.report` writes REPORT.md with the figures of :mod:`~phfdi.study.figures`. Public:
:class:`Multisignal`, :func:`decompose`, :func:`compress_energy`, :func:`variance_change_points`, imported
from their modules on first use (:mod:`phfdi_base.lazy`), so ``import phfdi.study`` imports no PyWavelets.
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["Multisignal", "compress_energy", "decompose", "variance_change_points"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .changepoint import variance_change_points
    from .compress import compress_energy
    from .multisignal import Multisignal, decompose
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
