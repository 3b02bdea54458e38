"""
What every ROS 2 node publishes besides its own topics: its log lines and its parameter events.

rcl gives each node a `/rosout` publisher (rcl_interfaces/msg/Log, unless `--disable-rosout-logs`)
and rclpy a `/parameter_events` publisher (rcl_interfaces/msg/ParameterEvent: new parameters on a
declaration, changed ones on a set). The embedded runtime does the same, with rcl's QoS, so that
`ros2 topic echo /rosout` or any subscriber, real rclpy included, reads them.
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Any, Callable, Sequence

from cloth_bench_ros.runtime.messages import message_class
from cloth_bench_ros.runtime.parameters import Parameter, ParameterType
from cloth_bench_ros.runtime.qos import DurabilityPolicy, HistoryPolicy, QoSProfile
import numpy as np

ROSOUT_TOPIC = '/rosout'
PARAMETER_EVENTS_TOPIC = '/parameter_events'
Log = message_class('rcl_interfaces/msg/Log')
ParameterEvent = message_class('rcl_interfaces/msg/ParameterEvent')
_Time = message_class('builtin_interfaces/msg/Time')
ParameterMsg = message_class('rcl_interfaces/msg/Parameter')
ParameterValue = message_class('rcl_interfaces/msg/ParameterValue')

# rcl_interfaces/msg/Log severities, as rcutils numbers them (and Python's logging does).
_SEVERITY = {
    logging.DEBUG: 10,
    logging.INFO: 20,
    logging.WARNING: 30,
    logging.ERROR: 40,
    logging.CRITICAL: 50,
}
VALUE_FIELDS = {
    ParameterType.BOOL: 'bool_value',
    ParameterType.INTEGER: 'integer_value',
    ParameterType.DOUBLE: 'double_value',
    ParameterType.STRING: 'string_value',
    ParameterType.BYTE_ARRAY: 'byte_array_value',
    ParameterType.BOOL_ARRAY: 'bool_array_value',
    ParameterType.INTEGER_ARRAY: 'integer_array_value',
    ParameterType.DOUBLE_ARRAY: 'double_array_value',
    ParameterType.STRING_ARRAY: 'string_array_value',
}


# rcl configures logging per process: a --log-level given to any init stays for later contexts.
PROCESS_LOG_LEVELS: dict[str, int] = {}


def rosout_qos() -> QoSProfile:
    """rcl_qos_profile_rosout_default: reliable, transient local, keep last 1000."""
    return QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def parameter_events_qos() -> QoSProfile:
    """rmw_qos_profile_parameter_events: reliable, volatile, keep last 1000."""
    return QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST)


def rcl_logger_name(namespace: str, name: str) -> str:
    """Return rcl's logger name of a node: its namespace's tokens and its name, dot-separated."""
    return '.'.join([*namespace.strip('/').split('/'), name]).lstrip('.')


def parameter_message(parameter: Parameter) -> Any:
    """Return rcl_interfaces/msg/Parameter of a parameter (type and the one field it uses)."""
    value = ParameterValue(type=int(parameter.type_))
    field = VALUE_FIELDS.get(parameter.type_)
    if field is None:  # NOT_SET: the type says it all
        pass
    elif isinstance(getattr(value, field), np.ndarray):  # numeric arrays, as the CDR codec wants
        items = [v[0] if isinstance(v, bytes) else v for v in parameter.value]
        setattr(value, field, np.asarray(items, dtype=getattr(value, field).dtype))
    else:
        as_list = field == 'string_array_value'
        setattr(value, field, list(parameter.value) if as_list else parameter.value)
    return ParameterMsg(name=parameter.name, value=value)


def parameter_event(
    node: str, stamp: Any, new: Sequence[Parameter] = (), changed: Sequence[Parameter] = ()
) -> Any:
    """Return the ParameterEvent rclpy publishes when a node declares or changes parameters."""
    return ParameterEvent(
        stamp=stamp,
        node=node,
        new_parameters=[parameter_message(p) for p in new],
        changed_parameters=[parameter_message(p) for p in changed],
    )


class RcutilsLogger:
    """A node's logger: Python logging for the console, and /rosout as rcl publishes it."""

    def __init__(
        self, logger: logging.Logger, name: str, node_name: str, rosout: Callable | None
    ) -> None:
        self._logger, self.name, self._node_name, self._rosout = logger, name, node_name, rosout

    def _log(self, level: int, msg: str) -> None:
        self._logger.log(level, '[%s]: %s', self._node_name, msg)
        threshold = self._logger.level or logging.INFO  # rcutils' default severity: INFO
        if self._rosout is not None and level >= threshold:
            caller = sys._getframe(2)
            now = time.time_ns()
            self._rosout(
                Log(
                    stamp=_Time(sec=now // 1_000_000_000, nanosec=now % 1_000_000_000),
                    level=_SEVERITY[level],
                    name=self.name,
                    msg=str(msg),
                    file=caller.f_code.co_filename,
                    function=caller.f_code.co_name,
                    line=caller.f_lineno,
                )
            )

    def set_level(self, level: int) -> None:
        self._logger.setLevel(level)

    def debug(self, msg: str) -> None:
        self._log(logging.DEBUG, msg)

    def info(self, msg: str) -> None:
        self._log(logging.INFO, msg)

    def warning(self, msg: str) -> None:
        self._log(logging.WARNING, msg)

    warn = warning

    def error(self, msg: str) -> None:
        self._log(logging.ERROR, msg)

    def fatal(self, msg: str) -> None:
        self._log(logging.CRITICAL, msg)
