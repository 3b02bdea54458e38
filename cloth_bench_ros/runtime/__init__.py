"""
The rclpy API the nodes are written against: real rclpy when it imports, else the embedded one.

Nodes import everything ROS from here, so the same node code runs under `ros2 run` with the real
sensor_msgs/geometry_msgs classes and, without ROS 2, in the embedded runtime with rosbags' types.
Set CLOTH_BENCH_EMBEDDED=1 to use the embedded runtime even where rclpy is installed.
"""

from __future__ import annotations

import os
from typing import Any, TYPE_CHECKING

from cloth_bench_ros.errors import InputError, is_rclpy_user_error, RCLPY_USER_ERRORS
from cloth_bench_ros.options import NODE_PARAMETERS, Option, OPTIONS

EMBEDDED = bool(os.environ.get('CLOTH_BENCH_EMBEDDED'))
if not EMBEDDED and not TYPE_CHECKING:
    try:
        import rclpy
    except ImportError:
        EMBEDDED = True

if EMBEDDED or TYPE_CHECKING:  # the type checker reads the embedded runtime's API
    from cloth_bench_ros.runtime import embedded as rclpy  # noqa: F811
    from cloth_bench_ros.runtime.embedded import Clock as _RosClock
    from cloth_bench_ros.runtime.embedded import ClockType as _ClockType
    from cloth_bench_ros.runtime.embedded import (
        deserialize_message,
        DurabilityPolicy,
        HistoryPolicy,
        Node,
        Parameter,
        ParameterDescriptor,
        QoSProfile,
        ReliabilityPolicy,
        serialize_message,
        SetParametersResult,
        SingleThreadedExecutor,
        Time,
    )
    from cloth_bench_ros.runtime.embedded import (
        DescribeParameters,
        GetParameters,
        GetParameterTypes,
        ListParameters,
        SetParameters,
        SetParametersAtomically,
    )
    from cloth_bench_ros.runtime.parameters import FloatingPointRange, IntegerRange
    from cloth_bench_ros.runtime.messages import (
        Clock,
        DiagnosticArray,
        DiagnosticStatus,
        Float64MultiArray,
        Header,
        KeyValue,
        MultiArrayDimension,
        MultiArrayLayout,
        Point,
        PointCloud2,
        PointField,
        Pose,
        PoseArray,
        Quaternion,
    )
    from cloth_bench_ros.runtime.rosout import ParameterMsg, ParameterValue
else:
    from builtin_interfaces.msg import Time as _TimeMsg  # noqa: F401
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange
    from rcl_interfaces.msg import ParameterDescriptor, ParameterValue, SetParametersResult
    from rcl_interfaces.srv import (
        DescribeParameters,
        GetParameters,
        GetParameterTypes,
        ListParameters,
        SetParameters,
        SetParametersAtomically,
    )
    from rclpy.clock import Clock as _RosClock
    from rclpy.clock_type import ClockType as _ClockType
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message, serialize_message
    from rclpy.time import Time
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import PointCloud2, PointField
    from std_msgs.msg import Float64MultiArray, Header, MultiArrayDimension, MultiArrayLayout

__all__ = [  # the API the nodes are written against, under either runtime
    'Clock',
    'declare_fixed',
    'declare_float',
    'declare_option',
    'DescribeParameters',
    'deserialize_message',
    'DiagnosticArray',
    'DiagnosticStatus',
    'DurabilityPolicy',
    'EMBEDDED',
    'Float64MultiArray',
    'FloatingPointRange',
    'GetParameters',
    'GetParameterTypes',
    'Header',
    'HistoryPolicy',
    'IntegerRange',
    'is_user_error',
    'KeyValue',
    'ListParameters',
    'make_qos',
    'message_type',
    'MESSAGE_TYPES',
    'MultiArrayDimension',
    'MultiArrayLayout',
    'Node',
    'Parameter',
    'ParameterDescriptor',
    'ParameterMsg',
    'ParameterValue',
    'Point',
    'PointCloud2',
    'PointField',
    'Pose',
    'PoseArray',
    'QoSProfile',
    'Quaternion',
    'rclpy',
    'ReliabilityPolicy',
    'serialize_message',
    'SetParameters',
    'SetParametersAtomically',
    'SetParametersResult',
    'SingleThreadedExecutor',
    'stamp_ns',
    'steady_clock',
    'Time',
    'typename',
    'USER_ERROR_CLASSES',
]

MESSAGE_TYPES = {
    'sensor_msgs/msg/PointCloud2': PointCloud2,
    'geometry_msgs/msg/PoseArray': PoseArray,
    'diagnostic_msgs/msg/DiagnosticArray': DiagnosticArray,
    'rosgraph_msgs/msg/Clock': Clock,
    'std_msgs/msg/Float64MultiArray': Float64MultiArray,
}


def message_type(typename: str) -> type:
    """Return the runtime's class for a ROS type name such as 'sensor_msgs/msg/PointCloud2'."""
    try:
        return MESSAGE_TYPES[typename]
    except KeyError:
        raise InputError(f'message type {typename} is not used by cloth_bench_ros') from None


def typename(msg_type: type) -> str:
    """Return the ROS type name of a runtime message class."""
    for name, cls in MESSAGE_TYPES.items():
        if cls is msg_type:
            return name
    raise ValueError(f'{msg_type} is not a message type used by cloth_bench_ros')


def stamp_ns(stamp) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def make_qos(depth: int, latched: bool = False, keep_all: bool = False) -> QoSProfile:
    """
    Reliable, keep-last `depth`; latched = transient local (late joiners get the last ones).

    keep_all: keep every sample until taken (a reader that must lose nothing, whatever its pace).
    """
    return QoSProfile(
        depth=depth,
        history=HistoryPolicy.KEEP_ALL if keep_all else HistoryPolicy.KEEP_LAST,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


# The user's input errors of rclpy (and of the embedded runtime's twins), matched by class name:
# errors.RCLPY_USER_ERRORS, under the names rclpy users know.
USER_ERROR_CLASSES = RCLPY_USER_ERRORS
is_user_error = is_rclpy_user_error


def option_descriptor(option: Option) -> Any:
    """Return the ParameterDescriptor of a declared option: description (unit, range), range."""
    descriptor = ParameterDescriptor(
        description=option.help_text(),
        dynamic_typing=option.type is float,
        read_only=option.read_only,
    )
    if option.low is not None and option.high is not None and not option.low_open:
        low = option.low
        if isinstance(option.unset, (int, float)) and not isinstance(option.unset, bool):
            low = min(low, option.unset)  # "not given" (-1) stays a value the node accepts
        if option.type is int:
            descriptor.integer_range = [
                IntegerRange(from_value=int(low), to_value=int(option.high), step=0)
            ]
        elif option.type is float:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(option.high), step=0.0)
            ]
    return descriptor


def declare_option(node, name: str) -> Any:
    """
    Declare options.OPTIONS[name] on `node` and return its value, checked by the declaration.

    A float option takes an integer too (`-p rate_hz:=1000`, see declare_float). A bad value is
    one InputError naming the node and the parameter.
    """
    option = OPTIONS[name]
    label = f'{node.get_name()}: parameter {name}'
    default = float(option.default) if option.type is float else option.default
    try:
        value = node.declare_parameter(name, default, option_descriptor(option)).value
    except Exception as exc:  # rclpy's own range check refused it
        if not is_rclpy_user_error(exc):
            raise
        raise InputError(f'{label}: {exc}') from None
    if option.type is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    return option.check(value, label)


_DECLARED: Any = object()  # the default of options.NODE_PARAMETERS[name]


def declare_fixed(node, name: str, default: Any = _DECLARED) -> Any:
    """
    Declare a parameter that a running node cannot change (read-only) and return its value.

    Its default is the declaration's (options.NODE_PARAMETERS), else one computed at start-up.

    Every node reads its parameters once, at start-up: `ros2 param set` on one is refused, by
    rclpy and the embedded runtime alike ('Trying to set a read-only parameter').
    """
    if default is _DECLARED:
        declared = NODE_PARAMETERS[name].default
        default = list(declared) if isinstance(declared, list) else declared  # not shared
    return node.declare_parameter(name, default, ParameterDescriptor(read_only=True)).value


def declare_float(node, name: str, default: float = _DECLARED) -> float:
    """
    Return a double parameter that also takes an integer (`-p rate_hz:=1000`).

    In rclpy and the embedded runtime alike.

    rclpy refuses an INTEGER override for a parameter declared DOUBLE; declared with dynamic
    typing, any type is accepted and this is the one place that keeps numbers and refuses the rest.
    """
    if default is _DECLARED:
        default = NODE_PARAMETERS[name].default
    value = node.declare_parameter(
        name, float(default), ParameterDescriptor(dynamic_typing=True, read_only=True)
    ).value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f'parameter {name}: expected a number (double or integer), got {value!r}')
    return float(value)


def steady_clock():
    """Return a steady clock for timers that must follow the wall clock even under use_sim_time."""
    return _RosClock(clock_type=_ClockType.STEADY_TIME)
