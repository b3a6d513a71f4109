"""Loop diagnosis from historian data: valve stiction and friends from OP, PV and SP alone.

``phfdi loop-diagnose FILE...`` (see docs/loop_diagnosis.md). Modules:

* :mod:`.readers` - historian exports (plant_loops TSV, CSV with a column mapping) -> Record;
* :mod:`.oscillation` - does the loop oscillate (Thornhill et al. 2003 regularity);
* :mod:`.controller` - the loop's PI law from the data (its action fixes the process gain sign);
* :mod:`.identify` - linear OP -> PV models (FOPTD, integrating, ARX) scored on held-out data;
* :mod:`.hammerstein` - valve blocks of :mod:`valve_actuator.blocks` fitted jointly with the linear part;
* :mod:`.diagnose` - evidence, verdict and the JSON report of one loop;
* :mod:`.report` - text and JSON formatting (keys shared with ``phfdi diagnose``);
* :mod:`.baselines` - Horch (1999) and He et al. (2007) stiction tests;
* :mod:`.evaluate` - leave-one-loop-out evaluation against labels;
* :mod:`.synthetic` - closed loops with known valve faults for the acceptance tests;
* :mod:`.batch` - many files on both cores.

The public names (``__all__``) are imported from their modules on first use (:mod:`phfdi_base.lazy`).
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["Oscillation", "Settings", "SyntheticLoop", "detect_oscillation", "diagnose_file", "diagnose_files",
           "diagnose_run", "format_report", "read_loop", "simulate_loop"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .batch import diagnose_files
    from .diagnose import Settings
    from .oscillation import Oscillation, detect_oscillation
    from .readers import read_loop
    from .report import format_report
    from .single import diagnose_file, diagnose_run
    from .synthetic import SyntheticLoop, simulate_loop
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
