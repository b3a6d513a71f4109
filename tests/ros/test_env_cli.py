"""Environment rules and the command line, without starting a graph."""

from __future__ import annotations

import subprocess

import pytest

from phfdi_base.errors import UserError
from phfdi_base.ros.env import ensure_localhost, graph_env, reserve_domain_id

from .conftest import node_cmd, phfdi_cmd


def test_localhost_discovery_is_set_when_missing_and_other_values_refused():
    env = {}
    ensure_localhost(env)
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    with pytest.raises(UserError, match="LOCALHOST"):
        ensure_localhost({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})
    assert graph_env(7, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"


def test_a_node_refuses_to_run_with_network_wide_discovery(ros_env):
    env = dict(ros_env, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET")
    out = subprocess.run(node_cmd("valve_actuator.node"), env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "LOCALHOST" in out.stderr


def test_reserved_domains_are_exclusive():
    with reserve_domain_id() as a, reserve_domain_id() as b:
        assert a.domain_id != b.domain_id
        with pytest.raises(UserError, match="in use"):
            reserve_domain_id(a.domain_id)


def test_an_exported_domain_id_is_used_or_refused_with_one_line(monkeypatch):
    """A ROS user's exported ROS_DOMAIN_ID was silently replaced by a free one (asked for 221, ran on 222)."""
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    with reserve_domain_id() as free, reserve_domain_id() as spare:
        pass  # two domains nobody holds, released again
    monkeypatch.setenv("ROS_DOMAIN_ID", str(free.domain_id))
    with reserve_domain_id() as taken:
        assert taken.domain_id == free.domain_id
        with pytest.raises(UserError, match=f"ROS domain {free.domain_id} \\(ROS_DOMAIN_ID \\(exported\\)\\) is in use"):
            reserve_domain_id()
        with reserve_domain_id(spare.domain_id) as other:  # --domain-id wins over the export
            assert other.domain_id == spare.domain_id
    monkeypatch.setenv("ROS_DOMAIN_ID", "eleven")
    with pytest.raises(UserError, match="ROS_DOMAIN_ID=eleven \\(exported\\): not a number"):
        reserve_domain_id()


def test_reserved_domains_stay_in_the_range_the_machine_allows(monkeypatch):
    monkeypatch.setenv("PHFDI_ROS_DOMAINS", "70-71")
    with reserve_domain_id() as a, reserve_domain_id() as b:
        assert {a.domain_id, b.domain_id} == {70, 71}
        with pytest.raises(UserError, match="no free ROS domain id \\(70..71\\)"):
            reserve_domain_id()
    monkeypatch.setenv("PHFDI_ROS_DOMAINS", "70-300")
    with pytest.raises(UserError, match="PHFDI_ROS_DOMAINS"):
        reserve_domain_id()


@pytest.mark.parametrize("args", [("launch", "--help"), ("bag", "info", "--help"), ("bag", "recover", "--help")])
def test_subcommands_explain_themselves_with_examples(args):
    out = subprocess.run(phfdi_cmd(*args), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "examples:" in out.stdout


def test_launch_refuses_a_bad_scenario_before_starting_anything(tmp_path):
    out = subprocess.run(phfdi_cmd("launch", "--set", "duration_s=-1", "--log-dir", str(tmp_path / "logs")),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "duration_s" in out.stderr
    assert not (tmp_path / "logs").exists()
