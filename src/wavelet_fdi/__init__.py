"""Online wavelet-residual fault detection. ROS-free; the detector node lives in :mod:`wavelet_fdi.learned_node`
(on :mod:`wavelet_fdi.node_base`).

:class:`LearnedDetector`, one detector for every reference kind (the paper loop's physics, a reference learned
from healthy records with :func:`learn`, the rig's estimator; :mod:`wavelet_fdi.references`), designed by
:class:`LearnedSettings` and built on :class:`CausalSwt` and :class:`CusumBank`. The paper's offline multisignal
analysis (Sections 6 and 7) is the application's, :mod:`phfdi.study`. The names in ``__all__`` are imported from
their modules on first use (:mod:`phfdi_base.lazy`), so ``import wavelet_fdi`` does not import scipy or PyWavelets.
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["CausalSwt", "CusumBank", "LearnedDetector", "LearnedModel", "LearnedSettings", "learn", "run_record"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .config import LearnedSettings
    from .filterbank import CausalSwt
    from .learned_detector import LearnedDetector, LearnedModel, learn, run_record
    from .statistics import CusumBank
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
