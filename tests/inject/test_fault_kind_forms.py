"""Each injectable fault carries its other forms (issue 37 item 3): the classes the rig estimator names it by, and
the catalogued block that models it in simulation. The rig benchmark and the rig simulator read or match these;
nothing translates one vocabulary into another by hand."""

from __future__ import annotations

import pytest

import ph_plant_sim.sensors  # noqa: F401  (registers the probe's blocks)
import valve_actuator.blocks  # noqa: F401  (registers the valve's blocks, among them the stem that holds)
from phfdi.benchmarks.rig_detection import CHANNELS, PROBE_CLASS, expected_class
from phfdi.inject_kinds import KINDS, PUMPS
from phfdi.rigsim.simulate import PROBE_FAULTS, ProbeFault
from phfdi_base.blocks import BLOCKS
from phfdi_base.faults import FAULTS
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
def test_the_rig_simulator_models_a_probe_fault_with_its_declared_block(name):
    block = KINDS[name].block
    assert block in BLOCKS, f"{name}: block {block!r} is not registered"
    built = ProbeFault(name, 10.0, None if KINDS[name].sizes is None else 0.5, seed=1).block(dt_s=1.0)
    assert type(built.block) is BLOCKS[block]
    catalogued = [f for f in FAULTS.values() if f.block == block]
    if catalogued and name != "probe_frozen":  # a frozen probe is the block that holds a valve's stem, on the probe
        assert catalogued[0].site == "ph_sensor", catalogued[0]


def test_a_kind_without_a_block_is_only_a_pump_fault():
    assert {n for n, k in KINDS.items() if k.block is None} == {n for n, k in KINDS.items() if k.family == "actuator"}
