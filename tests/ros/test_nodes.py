"""Single nodes as real processes: bad launch parameters, bad runtime changes, bad valve commands."""

from __future__ import annotations

import math
import subprocess
import time

import pytest

from phfdi_base import topics as T

from .conftest import close_context, node_cmd, phfdi_cmd

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


def test_invalid_launch_parameters_are_refused_with_one_line(ros_env):
    cases = {
        "range": (node_cmd("valve_actuator.node", command_max_pct="500.0"), ["command_max_pct", "[100, 200]"]),
        "type": (node_cmd("pi_controllers.node", ph_kp="6"), ["ph_kp", "double"]),
        "scenario": (node_cmd("ph_plant_sim.node", overrides="[duration_s=-5]"), ["duration_s"]),
        "fault": (node_cmd("ph_plant_sim.node", fault="nonsense"), ["unknown fault 'nonsense'"]),
        "choice": (node_cmd("phfdi.ros.recorder", path="/tmp/x.mcap", compression="gzip"), ["compression"]),
        "launch": (phfdi_cmd("launch", "--pace", "-1"), ["--pace"]),
        "unknown": (node_cmd("pi_controllers.node", ph_kpp="6.0"), ["unknown parameter ph_kpp", "ph_kp?"]),
    }
    procs = {k: subprocess.Popen(cmd, env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k, (cmd, _) in cases.items()}
    for key, proc in procs.items():
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, (key, err)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1, (key, err)
        for word in cases[key][1]:
            assert word in lines[0], (key, lines[0])
        assert "Traceback" not in err


def test_a_misspelt_detector_parameter_stops_the_launch_with_its_name():
    """--detector-param heartbeat_period=60 (no _s) was accepted and ignored without a word."""
    out = subprocess.run(phfdi_cmd("launch", "--detector-param", "heartbeat_period=60", "--set", "duration_s=200",
                                   "--set", "setpoints.ph.changes=[]"), capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "Traceback" not in out.stderr
    assert ("refused to start: unknown parameter heartbeat_period for node detector (did you mean "
            "heartbeat_period_s?)") in out.stderr, out.stderr
    assert "the graph did not connect; no sample ran" in out.stdout and "nan" not in out.stdout, out.stdout


def test_node_help_lists_parameters_with_ranges():
    out = subprocess.run(node_cmd("valve_actuator.node")[:3] + ["--help"], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0
    assert "command_max_pct" in out.stdout and "[100, 200]" in out.stdout and "changeable at runtime" in out.stdout


# ---- one valve node, driven by this test process over ROS --------------------------------
@pytest.fixture(scope="module")
def valve_node():
    """The valve node alone (a graph of itself), healthy scenario, on a domain of its own."""
    from phfdi_base.ros.env import graph_env, reserve_domain_id

    lease = reserve_domain_id()
    proc = subprocess.Popen(node_cmd("valve_actuator.node", fault="healthy", graph_nodes="[valve]",
                                     diagnostics_period_s="0.0"),
                            env=graph_env(lease.domain_id), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    yield proc, lease.domain_id
    proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    lease.release()


class _Driver:
    """This test's own node: publishes controller outputs, collects valve states and diagnostics."""

    def __init__(self, context, proc: subprocess.Popen) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from phfdi_interfaces.msg import ControllerOutput, ValveState
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        from phfdi_base.ros.graph_node import DATA_QOS

        self.proc = proc
        self.node = Node("valve_test_driver", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.states: dict[int, ValveState] = {}
        self.diagnostics: list = []
        self.pub = self.node.create_publisher(ControllerOutput, T.CONTROLLER.name, DATA_QOS)
        self.node.create_subscription(ValveState, T.VALVE_STATE.name,
                                      lambda m: self.states.__setitem__(m.stamp.sec, m), DATA_QOS)
        self.node.create_subscription(DiagnosticArray, T.DIAGNOSTICS.name, self.diagnostics.append, DATA_QOS)
        self.ControllerOutput = ControllerOutput
        self.k = -1

    def next_k(self) -> int:
        """Stamps only go forward (the valve ignores old ones), across the tests sharing the node."""
        self.k += 1
        return self.k

    def spin_until(self, condition, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            if self.proc.poll() is not None:
                raise AssertionError(f"the valve node exited: {self.proc.communicate()[1]}")
            assert time.monotonic() < deadline, "timed out waiting for the valve node"
            self.executor.spin_once(timeout_sec=0.1)

    def command(self, k: int, ph_pct: float, level_pct: float = 50.0):
        msg = self.ControllerOutput(ph_output_pct=ph_pct, level_output_pct=level_pct)
        msg.stamp.sec = k
        self.pub.publish(msg)
        self.spin_until(lambda: k in self.states)
        return self.states[k]

    def set_parameters(self, node_name: str, **values):
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        client = self.node.create_client(SetParameters, f"/{node_name}/set_parameters")
        self.spin_until(lambda: client.service_is_ready())
        future = client.call_async(SetParameters.Request(
            parameters=[Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]))
        self.spin_until(future.done)
        return future.result().results

    def get_parameter(self, node_name: str, name: str):
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python

        client = self.node.create_client(GetParameters, f"/{node_name}/get_parameters")
        self.spin_until(lambda: client.service_is_ready())
        future = client.call_async(GetParameters.Request(names=[name]))
        self.spin_until(future.done)
        return parameter_value_to_python(future.result().values[0])


@pytest.fixture(scope="module")
def driver(valve_node):
    import rclpy

    proc, domain_id = valve_node
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    d = _Driver(context, proc)
    # both directions matched before the first command (reliable delivery from the start)
    d.spin_until(lambda: d.pub.get_subscription_count() >= 1 and
                 d.node.count_publishers(T.VALVE_STATE.name) >= 1, timeout_s=120)
    yield d
    close_context(context, d.node, d.executor)


def test_valve_holds_non_finite_and_out_of_range_commands(driver):
    first = driver.command(driver.next_k(), 30.0)
    assert first.ph_position_pct == pytest.approx(30.0)
    rejected_before = first.ph_rejected_commands
    held = driver.command(driver.next_k(), math.nan)
    assert held.ph_position_pct == first.ph_position_pct
    assert held.ph_rejected_commands == rejected_before + 1 and math.isnan(held.ph_command_pct)
    moved = driver.command(driver.next_k(), 35.0)
    assert moved.ph_position_pct == pytest.approx(35.0)
    for bad in (1e9, -50.0, math.inf):
        state = driver.command(driver.next_k(), bad)
        assert state.ph_position_pct == moved.ph_position_pct
    assert state.ph_rejected_commands == rejected_before + 4
    total = f"{state.ph_rejected_commands} command(s) held"
    driver.spin_until(lambda: any(total in s.message for a in driver.diagnostics for s in a.status))
    report = [s for a in driver.diagnostics for s in a.status if total in s.message][-1]
    values = {kv.key: kv.value for kv in report.values}
    assert int(values["not_finite"]) + int(values["out_of_range"]) == state.ph_rejected_commands
    assert int(values["out_of_range"]) >= 2 and int(values["not_finite"]) >= 2
    assert driver.command(driver.next_k(), 40.0).ph_position_pct == pytest.approx(40.0)  # alive, moving


def test_bad_runtime_parameter_changes_are_rejected_and_the_old_value_kept(driver):
    (result,) = driver.set_parameters("valve", command_max_pct=500.0)
    assert not result.successful and "command_max_pct" in result.reason
    assert driver.get_parameter("valve", "command_max_pct") == 106.25
    (result,) = driver.set_parameters("valve", fault="nonsense")
    assert not result.successful and "unknown fault 'nonsense'" in result.reason
    (result,) = driver.set_parameters("valve", fault="probe_delay")
    assert not result.successful and "ph sensor" in result.reason
    (result,) = driver.set_parameters("valve", scenario="henson_seborg")
    assert not result.successful and "read-only" in result.reason
    assert driver.get_parameter("valve", "fault") == "healthy"


def test_a_valve_fault_can_be_switched_on_at_runtime(driver):
    driver.command(driver.next_k(), 30.0)
    try:
        results = driver.set_parameters("valve", fault="blocking", fault_onset_s=0.0)
        assert all(r.successful for r in results), [r.reason for r in results]
        assert driver.get_parameter("valve", "fault") == "blocking"
        stuck = driver.command(driver.next_k(), 60.0)  # a seized stem stays where it was
        assert stuck.ph_position_pct == pytest.approx(30.0) and stuck.ph_fault_severity == 1.0
        driver.spin_until(lambda: any("blocking" in kv.value for a in driver.diagnostics for s in a.status
                                      for kv in s.values))
    finally:  # the other tests of this module share the node
        driver.set_parameters("valve", fault="healthy", fault_onset_s=-1.0)
    assert driver.command(driver.next_k(), 60.0).ph_position_pct == pytest.approx(60.0)
