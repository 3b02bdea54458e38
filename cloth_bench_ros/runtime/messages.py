"""
ROS 2 message classes of the embedded runtime: rosbags' types, constructible with defaults.

rosbags' message classes are dataclasses whose every field is required; rclpy's take keyword
arguments and default the rest. The classes here behave like rclpy's, serialise to the same CDR
bytes (through rosbags) and are what `cloth_bench_ros.runtime` exports when rclpy is absent.
"""

from __future__ import annotations

from typing import Any, Callable, TYPE_CHECKING

from cloth_bench_ros.data.messages import TYPESTORE
import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys.stores import ros2_humble as _store  # the type stubs' bases

_NUMPY = {
    'bool': np.bool_,
    'byte': np.uint8,
    'char': np.uint8,
    'int8': np.int8,
    'uint8': np.uint8,
    'int16': np.int16,
    'uint16': np.uint16,
    'int32': np.int32,
    'uint32': np.uint32,
    'int64': np.int64,
    'uint64': np.uint64,
    'float32': np.float32,
    'float64': np.float64,
}
_classes: dict[str, type] = {}


def _factory(node: tuple) -> Callable[[], Any]:
    """Return a zero-argument maker of a field's default value, as rclpy's constructors give it."""
    kind, detail = node[0], node[1]
    if kind == Nodetype.BASE:  # an immutable constant
        name = detail[0]
        value: Any = (
            ''
            if name == 'string'
            else False if name == 'bool' else 0.0 if name.startswith('float') else 0
        )
        return lambda: value
    if kind == Nodetype.NAME:  # a message; its class is looked up on first use (deep nesting)
        nested: list[type] = []

        def make_nested() -> Any:
            if not nested:
                nested.append(message_class(detail))
            return nested[0]()

        return make_nested
    (inner_kind, inner), length = detail
    numeric = inner_kind == Nodetype.BASE and inner[0] in _NUMPY
    if kind == Nodetype.ARRAY:  # fixed size
        if numeric:
            return lambda: np.zeros(length, dtype=_NUMPY[inner[0]])
        element = _factory((inner_kind, inner))
        return lambda: [element() for _ in range(length)]
    if numeric:  # Nodetype.SEQUENCE
        return lambda: np.zeros(0, dtype=_NUMPY[inner[0]])
    return list


def message_class(typename: str) -> type:
    """Return a subclass of rosbags' class for `typename` whose constructor defaults each field."""
    if typename not in _classes:
        base = TYPESTORE.types[typename]
        factories = [(name, _factory(node)) for name, node in TYPESTORE.fielddefs[typename][1]]
        every_field = len(factories)

        def __init__(self: Any, **kwargs: Any) -> None:
            if len(kwargs) != every_field:  # a field not given gets its default
                for name, make in factories:
                    if name not in kwargs:
                        kwargs[name] = make()
            base.__init__(self, **kwargs)

        _classes[typename] = type(typename.rsplit('/', 1)[-1], (base,), {'__init__': __init__})
    return _classes[typename]


def with_numpy_arrays(msg: Any, typename: str) -> Any:
    """
    Make every numeric array field of `msg` a numpy array, as rosbags' CDR codec wants.

    rclpy accepts lists (and bytes objects in byte arrays); a message built that way is fixed up
    here before it is serialised.
    """
    fields: Any = TYPESTORE.fielddefs[typename][1]  # rosbags' node tuples, read as in _factory
    for name, (kind, detail) in fields:
        value = getattr(msg, name)
        if kind == Nodetype.NAME:
            with_numpy_arrays(value, detail)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            (inner_kind, inner), _ = detail
            if inner_kind == Nodetype.NAME:
                for item in value:
                    with_numpy_arrays(item, inner)
            elif (
                inner_kind == Nodetype.BASE
                and inner[0] in _NUMPY
                and not isinstance(value, np.ndarray)
            ):
                items = [v[0] if isinstance(v, bytes) else v for v in value]
                setattr(msg, name, np.asarray(items, dtype=_NUMPY[inner[0]]))
    return msg


if TYPE_CHECKING:  # what the type checker reads: rosbags' classes, rclpy's keyword constructor

    class _Keywords:
        def __init__(self, **kwargs: Any) -> None:
            pass

    class Time(_Keywords, _store.builtin_interfaces__msg__Time):
        pass

    class Header(_Keywords, _store.std_msgs__msg__Header):
        pass

    class String(_Keywords, _store.std_msgs__msg__String):
        pass

    class Clock(_Keywords, _store.rosgraph_msgs__msg__Clock):
        pass

    class Point(_Keywords, _store.geometry_msgs__msg__Point):
        pass

    class Quaternion(_Keywords, _store.geometry_msgs__msg__Quaternion):
        pass

    class Pose(_Keywords, _store.geometry_msgs__msg__Pose):
        pass

    class PoseArray(_Keywords, _store.geometry_msgs__msg__PoseArray):
        pass

    class PointField(_Keywords, _store.sensor_msgs__msg__PointField):
        pass

    class PointCloud2(_Keywords, _store.sensor_msgs__msg__PointCloud2):
        pass

    class KeyValue(_Keywords, _store.diagnostic_msgs__msg__KeyValue):
        pass

    class DiagnosticStatus(_Keywords, _store.diagnostic_msgs__msg__DiagnosticStatus):
        pass

    class DiagnosticArray(_Keywords, _store.diagnostic_msgs__msg__DiagnosticArray):
        pass

    class MultiArrayDimension(_Keywords, _store.std_msgs__msg__MultiArrayDimension):
        pass

    class MultiArrayLayout(_Keywords, _store.std_msgs__msg__MultiArrayLayout):
        pass

    class Float64MultiArray(_Keywords, _store.std_msgs__msg__Float64MultiArray):
        pass

else:
    Time = message_class('builtin_interfaces/msg/Time')
    Header = message_class('std_msgs/msg/Header')
    String = message_class('std_msgs/msg/String')
    Clock = message_class('rosgraph_msgs/msg/Clock')
    Point = message_class('geometry_msgs/msg/Point')
    Quaternion = message_class('geometry_msgs/msg/Quaternion')
    Pose = message_class('geometry_msgs/msg/Pose')
    PoseArray = message_class('geometry_msgs/msg/PoseArray')
    PointField = message_class('sensor_msgs/msg/PointField')
    PointCloud2 = message_class('sensor_msgs/msg/PointCloud2')
    KeyValue = message_class('diagnostic_msgs/msg/KeyValue')
    DiagnosticStatus = message_class('diagnostic_msgs/msg/DiagnosticStatus')
    DiagnosticArray = message_class('diagnostic_msgs/msg/DiagnosticArray')
    MultiArrayDimension = message_class('std_msgs/msg/MultiArrayDimension')
    MultiArrayLayout = message_class('std_msgs/msg/MultiArrayLayout')
    Float64MultiArray = message_class('std_msgs/msg/Float64MultiArray')
