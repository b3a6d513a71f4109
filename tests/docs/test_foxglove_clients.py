"""The README says which Foxglove clients connect to the live view (issue 36 item 10), and says it right: the
server accepts the subprotocol the README names and refuses the former one it names (a real server on a free
port; no ROS)."""

from __future__ import annotations

from pathlib import Path

import pytest

from phfdi_base import live_view

ROOT = Path(__file__).resolve().parents[2]
CURRENT, FORMER = "foxglove.sdk.v1", "foxglove.websocket.v1"


def _accepts(port: int, subprotocol: str) -> bool:
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    try:
        with connect(f"ws://127.0.0.1:{port}", subprotocols=[subprotocol], open_timeout=10) as ws:
            return ws.subprotocol == subprotocol
    except InvalidStatus:
        return False


def test_the_readme_names_the_subprotocol_the_live_view_accepts_and_the_one_it_refuses():
    pytest.importorskip("websockets")
    view = live_view.LiveView(port=0)
    try:
        accepted = {p: _accepts(view.port, p) for p in (CURRENT, FORMER)}
    finally:
        view.stop()
    assert accepted == {CURRENT: True, FORMER: False}
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert f"`{CURRENT}` only" in readme
    assert f"only the former name `{FORMER}` are refused" in readme
