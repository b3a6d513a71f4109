"""A detector node on your plant's own topics starts as the README says (issue 36 item 1).

``python -m wavelet_fdi.learned_node --ros-args -p reference:=ref.json -p channel_map_file:=...`` (no
``graph_nodes``) used to wait at its start barrier for the simulator's plant, controllers and valve, which a plant
of your own never starts, and stopped itself after ``connect_timeout_s`` (60 s). With a channel map the barrier now
waits for no other node unless ``graph_nodes`` says so. The tests shorten ``connect_timeout_s`` to 1 s rather than
wait out the default 60 s: the node must connect at once and still run well past that limit.
Real processes on a ROS domain reserved for the test (loopback discovery only).
"""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from wavelet_fdi.channel_map import load_channel_map
from wavelet_fdi.learned_detector import LearnedModel, learn

from .conftest import node_cmd
from .test_foreign_topics import wait_for_event

pytestmark = [pytest.mark.ros, pytest.mark.timeout(240)]

ROOT = Path(__file__).resolve().parents[2]
SKAB_MAP = ROOT / "config" / "channel_map_skab.yaml"  # the map the README's command names
START_S = 120  # what a node may take to start on 2 loaded cores: the test waits on the event, not the time
CONNECT_TIMEOUT_S = 1.0
RUNS_PAST_S = 3 * CONNECT_TIMEOUT_S


@pytest.fixture
def skab_like_reference(tmp_path) -> Path:
    """A learned reference with the channels of the shipped SKAB map (synthetic healthy rows: no shared data)."""
    channels = load_channel_map(SKAB_MAP).channels
    rows = np.random.default_rng(36).normal(size=(600, len(channels)))
    path = tmp_path / "ref.json"
    learn(rows, channels).save(path)
    return path


@pytest.fixture
def physics_map(tmp_path) -> Path:
    """A map of the shipped physics reference's channels onto topics of a plant of one's own."""
    path = tmp_path / "physics_map.yaml"
    path.write_text("channels:\n" + "".join(f"  {c}: {{topic: /my_plant/{c}, type: std_msgs/msg/Float64}}\n"
                                            for c in LearnedModel.load("paper_physics").channels))
    return path


def _stop(proc: subprocess.Popen) -> tuple[str, str]:
    proc.send_signal(signal.SIGTERM)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return out.decode(errors="replace"), err.decode(errors="replace")


@pytest.mark.parametrize("detector", ["learned", "physics"])
def test_a_mapped_node_without_graph_nodes_waits_for_no_simulator_node(detector, skab_like_reference, physics_map,
                                                                        ros_env, tmp_path):
    if detector == "learned":  # the README's command, as written, plus the shortened limit
        params = {"reference": skab_like_reference, "channel_map_file": SKAB_MAP}
    else:  # the shipped physics reference on a plant of one's own
        params = {"reference": "paper_physics", "channel_map_file": physics_map}
    proc = subprocess.Popen(node_cmd("wavelet_fdi.learned_node", **params, connect_timeout_s=CONNECT_TIMEOUT_S),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ros_env, cwd=tmp_path)
    try:
        event, _ = wait_for_event(proc, "startup", START_S)  # printed when the start barrier connects
        assert event.get("event") == "startup", event
        connected = time.monotonic()
        while time.monotonic() - connected < RUNS_PAST_S:
            assert proc.poll() is None, "the node stopped"
            time.sleep(0.1)
    finally:
        out, err = _stop(proc)
    assert proc.returncode == 0, err
    assert "did not connect" not in err and "waiting for node(s)" not in err and "Traceback" not in err, err
    assert "the start barrier waits for no other node" in err
    assert '"event": "detector_done"' in out


def test_graph_nodes_given_with_a_map_is_still_waited_for(skab_like_reference, ros_env, tmp_path):
    """A mapped node in a graph of yours (graph_nodes given) waits for those nodes, as before."""
    proc = subprocess.run(node_cmd("wavelet_fdi.learned_node", reference=skab_like_reference, channel_map_file=SKAB_MAP,
                                   graph_nodes="[detector, my_plant]", connect_timeout_s=CONNECT_TIMEOUT_S),
                          capture_output=True, text=True, timeout=START_S, env=ros_env, cwd=tmp_path)
    assert proc.returncode == 3, proc.stderr
    assert "did not connect within 1 s: waiting for node(s) my_plant" in proc.stderr
    assert "waits for no other node" not in proc.stderr
