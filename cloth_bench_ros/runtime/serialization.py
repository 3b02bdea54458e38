"""rclpy.serialization for the embedded runtime: CDR through rosbags."""

from __future__ import annotations

from typing import Any

from cloth_bench_ros.data import messages as cdr


def serialize_message(msg: Any) -> bytes:
    return cdr.serialize(msg)


def deserialize_message(data: bytes, msg_type: Any) -> Any:
    return cdr.deserialize(data, msg_type.__msgtype__)
