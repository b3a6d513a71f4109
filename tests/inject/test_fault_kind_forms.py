"""Each injectable fault carries its other forms (issue 37 item 3): the classes the rig estimator names it by, and
its fault catalogue entry (same name) whose block models it in simulation. The rig benchmark and the rig simulator
read or match these; nothing translates one vocabulary into another by hand."""

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
    assert kind.isolated_as, f"{name}: no isolation class declared"
    if kind.family == "sensor":
        assert set(kind.isolation_classes()) <= set(SENSOR_CLASSES)
    else:
        for pump in PUMPS:
            (cls,) = kind.isolation_classes(pump)
            assert cls.startswith("pump:") and cls.removeprefix("pump:") in CHANNELS, cls


def test_the_rig_benchmark_reads_the_declaration():
    assert set(PROBE_CLASS) == {n for n, k in KINDS.items() if k.family == "sensor"}
    assert expected_class("probe_drift", None) == ["probe_drift", "probe_bias"]  # the exact class first
    assert expected_class("pump_low", "base") == ["pump:base_flow_ml_s"]


@pytest.mark.parametrize("name", PROBE_FAULTS)
def test_a_probe_fault_is_the_catalogue_entry_of_its_name_and_the_rig_simulator_runs_its_block(name):
    fault = catalogue()[name]
    assert fault.site == "ph_sensor" and fault.block in BLOCKS, fault
    built = ProbeFault(name, 10.0, None if KINDS[name].sizes is None else 0.5, seed=1).block(dt_s=1.0)
    assert type(built.block) is BLOCKS[fault.block]


def test_the_estimators_sensor_classes_are_catalogued_probe_faults():
    assert set(SENSOR_CLASSES) <= {n for n, f in catalogue().items() if f.site == "ph_sensor"}


def test_only_the_pump_faults_have_no_catalogue_entry():
    assert {n for n in KINDS if n not in catalogue()} == {n for n, k in KINDS.items() if k.family == "actuator"}
