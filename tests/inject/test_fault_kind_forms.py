"""Each injectable fault is one fault catalogue entry carrying all of its forms (issue 37 item 3): the block that
models it in simulation, how ``phfdi inject`` hides it (unit, sizes) and the classes the rig estimator names it by.
The rig benchmark, the rig simulator and ``phfdi inject`` read the entry; nothing translates one vocabulary into
another by hand."""

from __future__ import annotations

import pytest

from phfdi.benchmarks.rig_detection import CHANNELS, PROBE_CLASS, expected_class
from phfdi.faults import catalogue
from phfdi.inject_kinds import KINDS, PUMPS
from phfdi.rigsim.simulate import PROBE_FAULTS, ProbeFault
from phfdi_base.blocks import BLOCKS
from wavelet_fdi.estimator_isolation import SENSOR_CLASSES


@pytest.mark.parametrize("name", sorted(KINDS))
def test_every_kind_is_named_by_classes_the_isolation_has(name):
    kind = KINDS[name]
    assert kind.inject.isolated_as, f"{name}: no isolation class declared"
    if kind.family == "sensor":
        assert set(kind.inject.isolation_classes()) <= set(SENSOR_CLASSES)
    else:
        for pump in PUMPS:
            (cls,) = kind.inject.isolation_classes(pump)
            assert cls.startswith("pump:") and cls.removeprefix("pump:") in CHANNELS, cls


def test_the_rig_benchmark_reads_the_declaration():
    assert set(PROBE_CLASS) == {n for n, k in KINDS.items() if k.family == "sensor"}
    assert expected_class("probe_drift", None) == ["probe_drift", "probe_bias"]  # the exact class first
    assert expected_class("pump_low", "base") == ["pump:base_flow_ml_s"]


@pytest.mark.parametrize("name", PROBE_FAULTS)
def test_a_probe_fault_is_the_catalogue_entry_of_its_name_and_the_rig_simulator_runs_its_block(name):
    fault = catalogue()[name]
    assert fault.site == "ph_sensor" and fault.block in BLOCKS, fault
    built = ProbeFault(name, 10.0, None if KINDS[name].inject.sizes is None else 0.5, seed=1).block(dt_s=1.0)
    assert type(built.block) is BLOCKS[fault.block]


def test_the_estimators_sensor_classes_are_catalogued_probe_faults():
    assert set(SENSOR_CLASSES) <= {n for n, f in catalogue().items() if f.site == "ph_sensor"}


def test_every_injectable_kind_is_the_catalogue_entry_of_its_name():
    """The kinds are the catalogue's entries with an injection form, the probe's and the dosing pumps', each modelled
    by a registered block (a pump's by its delivery curve) and kept out of the presets, the isolation's bank and the
    model diagnosis's candidates, which have no rig pump to fit."""
    entries = catalogue()
    assert {n for n, f in entries.items() if f.inject is not None} == set(KINDS)
    assert all(KINDS[n] is entries[n] for n in KINDS)
    assert {k.family for k in KINDS.values()} == {"sensor", "actuator"}
    pumps = {n: k for n, k in KINDS.items() if k.family == "actuator"}
    assert set(pumps) == {"pump_low", "pump_high", "pump_stuck"}
    for name, fault in pumps.items():
        assert fault.site == "pump" and fault.block == "pump_curve" and fault.block in BLOCKS, fault
        assert not (fault.preset or fault.isolate or fault.candidate), name
