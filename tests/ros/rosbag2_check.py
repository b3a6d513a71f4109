"""Reading our bags as rosbag2 tools do: rosbags' rosbag2 reader on the bare .mcap and on a rosbag2 folder."""

from __future__ import annotations

import os
from pathlib import Path

import yaml
from mcap.reader import make_reader

from phfdi import rosbag2_meta


def rosbag2_record(bag: Path) -> dict:
    """The bag's ``rosbag2`` metadata record, parsed (what ``ros2 bag info`` reads from a bare .mcap)."""
    with open(bag, "rb") as f:
        records = [m for m in make_reader(f).iter_metadata() if m.name == rosbag2_meta.RECORD_NAME]
    assert len(records) == 1, [m.name for m in records]
    return yaml.safe_load(records[0].metadata[rosbag2_meta.RECORD_KEY])


def as_rosbag2_folder(bag: Path, folder: Path) -> Path:
    """A rosbag2 folder of the bag: the file (hard link) and a metadata.yaml made of its ``rosbag2`` record, as
    ``ros2 bag record`` leaves them, so that rosbags' DirectoryReader checks the record with its v9 parser."""
    folder.mkdir()
    os.link(bag, folder / bag.name)
    meta = {"rosbag2_bagfile_information": rosbag2_record(bag)}
    (folder / "metadata.yaml").write_text(yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")
    return folder


def read_with_rosbags(path: Path) -> dict:
    """What rosbags' rosbag2 Reader sees in a bag (.mcap file or rosbag2 folder): per topic its type, its count
    from the metadata and the messages read, and its QoS profiles; the total message count."""
    from rosbags.rosbag2 import Reader

    with Reader(path) as reader:
        read: dict[str, int] = {}
        for conn, _t, _raw in reader.messages():
            read[conn.topic] = read.get(conn.topic, 0) + 1
        topics = {c.topic: {"type": c.msgtype, "count": c.msgcount, "read": read.get(c.topic, 0),
                            "qos": c.ext.offered_qos_profiles} for c in reader.connections}
        return {"topics": topics, "message_count": reader.message_count}
