"""Loop diagnosis from historian data: valve stiction and friends from OP, PV and SP alone.

``phfdi loop-diagnose FILE...`` (see docs/loop_diagnosis.md). Modules:

* :mod:`.readers` - historian exports (plant_loops TSV, CSV with a column mapping) -> Run;
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
"""
