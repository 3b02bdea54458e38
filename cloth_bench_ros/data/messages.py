"""
ROS 2 message types without ROS: one `rosbags` typestore (ROS 2 Humble) for the project.

`serialize`/`deserialize` turn messages into CDR bytes and back; the bytes are those that
rclpy would put on the wire, so bags written here play in `ros2 bag play` and Foxglove.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

from cloth_bench_ros.errors import ClothBenchError
from rosbags.typesys import get_types_from_msg, get_typestore, Stores
from rosbags.typesys.store import Typestore

# rcl_interfaces/srv: request and response fields (the .srv files' two halves).
SERVICE_DEFINITIONS = {
    'rcl_interfaces/srv/DescribeParameters': (
        'string[] names',
        'ParameterDescriptor[] descriptors',
    ),
    'rcl_interfaces/srv/GetParameters': ('string[] names', 'ParameterValue[] values'),
    'rcl_interfaces/srv/GetParameterTypes': ('string[] names', 'uint8[] types'),
    'rcl_interfaces/srv/ListParameters': (
        'uint64 DEPTH_RECURSIVE=0\nstring[] prefixes\nuint64 depth',
        'ListParametersResult result',
    ),
    'rcl_interfaces/srv/SetParameters': (
        'Parameter[] parameters',
        'SetParametersResult[] results',
    ),
    'rcl_interfaces/srv/SetParametersAtomically': (
        'Parameter[] parameters',
        'SetParametersResult result',
    ),
}


def _project_typestore() -> Typestore:
    """
    Return ROS 2 Humble's type store with the rcl_interfaces services' request and response types.

    rosbags has no srv types; the parameter services of every node need these. They are part of
    the store from its making: no module changes it afterwards.
    """
    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict = {}
    for srv_type, halves in SERVICE_DEFINITIONS.items():
        for suffix, text in zip(('_Request', '_Response'), halves):
            # Parsed as a msg of the same package, so that `Parameter` names rcl_interfaces/msg/.
            parsed = get_types_from_msg(text, srv_type.replace('/srv/', '/msg/') + suffix)
            types.update({n.replace('/msg/', '/srv/'): fields for n, fields in parsed.items()})
    store.register(types)
    return store


TYPESTORE = _project_typestore()

POINTCLOUD2 = 'sensor_msgs/msg/PointCloud2'
POSE_ARRAY = 'geometry_msgs/msg/PoseArray'
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'
HEADER = 'std_msgs/msg/Header'


class MessageTypeError(ClothBenchError, ValueError):
    """A message type name that the typestore does not know."""


def msg_class(msgtype: str) -> type:
    """Return the rosbags dataclass of a message type name such as "std_msgs/msg/Header"."""
    try:
        return TYPESTORE.types[msgtype]
    except KeyError:
        raise MessageTypeError(f'unknown message type {msgtype!r}') from None


def serialize(msg: Any, msgtype: str | None = None) -> bytes:
    """CDR (little-endian) bytes of a rosbags message; msgtype defaults to the message's own."""
    msgtype = msgtype or msg.__msgtype__
    msg_class(msgtype)
    return bytes(TYPESTORE.serialize_cdr(msg, msgtype))


def deserialize(cdr: bytes | memoryview, msgtype: str) -> Any:
    """Return the rosbags message object encoded by CDR bytes."""
    msg_class(msgtype)
    return TYPESTORE.deserialize_cdr(cdr, msgtype)


@lru_cache(maxsize=None)
def msgdef(msgtype: str) -> str:
    """Return a type's `ros2msg` definition with its dependencies, as MCAP schemas carry it."""
    msg_class(msgtype)
    text, _ = TYPESTORE.generate_msgdef(msgtype, ros_version=2)
    return text


@lru_cache(maxsize=None)
def type_hash(msgtype: str) -> str:
    """Return the RIHS01 type description hash of a type (rosbag2 metadata version 8+)."""
    msg_class(msgtype)
    return TYPESTORE.hash_rihs01(msgtype)


@lru_cache(maxsize=None)
def has_header(msgtype: str) -> bool:
    """Return True if the type's first field is a std_msgs/Header (its stamp opens the payload)."""
    msg_class(msgtype)
    _, fields = TYPESTORE.fielddefs[msgtype]
    if not fields:
        return False
    name, (_, detail) = fields[0]
    return name == 'header' and detail == HEADER


def time_msg(stamp_ns: int) -> Any:
    """builtin_interfaces/Time of an integer nanosecond stamp."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return msg_class('builtin_interfaces/msg/Time')(sec=sec, nanosec=nanosec)


def header(stamp_ns: int, frame_id: str = 'world') -> Any:
    """std_msgs/Header with an integer nanosecond stamp."""
    return msg_class(HEADER)(stamp=time_msg(stamp_ns), frame_id=frame_id)


def stamp_ns(stamp: Any) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
