"""The rclpy API the nodes are written against: real rclpy when it imports, else the embedded one.

Nodes import everything ROS from here, so the same node code runs under `ros2 run` with the real
sensor_msgs/geometry_msgs classes and, without ROS 2, in the embedded runtime with rosbags' types.
Set CLOTH_BENCH_EMBEDDED=1 to use the embedded runtime even where rclpy is installed.
"""

from __future__ import annotations

import os

EMBEDDED = bool(os.environ.get("CLOTH_BENCH_EMBEDDED"))
if not EMBEDDED:
    try:
        import rclpy
    except ImportError:
        EMBEDDED = True

if EMBEDDED:
    from cloth_bench_ros.runtime import embedded as rclpy  # noqa: F811
    from cloth_bench_ros.runtime.embedded import (
        DurabilityPolicy,
        Node,
        Parameter,
        QoSProfile,
        ReliabilityPolicy,
        SingleThreadedExecutor,
        Time,
        deserialize_message,
        serialize_message,
    )
    from cloth_bench_ros.runtime.messages import (
        Clock,
        DiagnosticArray,
        DiagnosticStatus,
        Header,
        KeyValue,
        Point,
        PointCloud2,
        PointField,
        Pose,
        PoseArray,
        Quaternion,
    )
else:
    from builtin_interfaces.msg import Time as _TimeMsg  # noqa: F401
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message, serialize_message
    from rclpy.time import Time
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import PointCloud2, PointField
    from std_msgs.msg import Header

MESSAGE_TYPES = {
    "sensor_msgs/msg/PointCloud2": PointCloud2,
    "geometry_msgs/msg/PoseArray": PoseArray,
    "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray,
    "rosgraph_msgs/msg/Clock": Clock,
}


def message_type(typename: str) -> type:
    """The runtime's class for a ROS type name such as 'sensor_msgs/msg/PointCloud2'."""
    try:
        return MESSAGE_TYPES[typename]
    except KeyError:
        raise ValueError(f"message type {typename} is not used by cloth_bench_ros") from None


def typename(msg_type: type) -> str:
    """The ROS type name of a runtime message class."""
    for name, cls in MESSAGE_TYPES.items():
        if cls is msg_type:
            return name
    raise ValueError(f"{msg_type} is not a message type used by cloth_bench_ros")


def stamp_ns(stamp) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def make_qos(depth: int, latched: bool = False) -> QoSProfile:
    """Reliable, keep-last `depth`; latched = transient local (late joiners get the last ones)."""
    return QoSProfile(
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
