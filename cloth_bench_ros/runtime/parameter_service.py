"""
The parameter services every node offers, with rclpy's semantics (rclpy/parameter_service.py).

`<node>/list_parameters`, `get_parameters`, `get_parameter_types`, `describe_parameters`,
`set_parameters` and `set_parameters_atomically` (rcl_interfaces/srv), on the parameters QoS:
what `ros2 param list|get|set|describe|dump` call. A name that is not declared empties the whole
answer, as rclpy does; a change the node refuses comes back as an unsuccessful SetParametersResult
with the node's reason (read-only, type, or the node's own on-set callback).
"""

from __future__ import annotations

from typing import Any

from cloth_bench_ros.runtime.messages import message_class
from cloth_bench_ros.runtime.parameter_errors import (
    ParameterNotDeclaredException,
    ParameterUninitializedException,
)
from cloth_bench_ros.runtime.parameters import (
    Parameter,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from cloth_bench_ros.runtime.rosout import parameter_message, VALUE_FIELDS
from cloth_bench_ros.runtime.services import (
    DescribeParameters,
    GetParameters,
    GetParameterTypes,
    ListParameters,
    parameters_qos,
    SetParameters,
    SetParametersAtomically,
)
import numpy as np

PARAMETER_SEPARATOR = '.'
_DescriptorMsg = message_class('rcl_interfaces/msg/ParameterDescriptor')
_ListParametersResult = message_class('rcl_interfaces/msg/ListParametersResult')
_SetParametersResultMsg = message_class('rcl_interfaces/msg/SetParametersResult')


def descriptor_message(descriptor: ParameterDescriptor) -> Any:
    """Return rcl_interfaces/msg/ParameterDescriptor of a descriptor."""
    return _DescriptorMsg(
        name=descriptor.name,
        type=int(descriptor.type),
        description=descriptor.description,
        read_only=descriptor.read_only,
        dynamic_typing=descriptor.dynamic_typing,
    )


def parameter_from_message(msg: Any) -> Parameter:
    """Return the Parameter an rcl_interfaces/msg/Parameter carries (rclpy from_parameter_msg)."""
    type_ = ParameterType(msg.value.type)
    field = VALUE_FIELDS.get(type_)
    value = getattr(msg.value, field) if field else None
    if isinstance(value, np.ndarray):
        byte_array = type_ == ParameterType.BYTE_ARRAY
        value = [bytes([v]) for v in value] if byte_array else value.tolist()
    elif isinstance(value, list):
        value = list(value)
    return Parameter(msg.name, type_, value)


def list_parameters(names: list[str], prefixes: list[str], depth: int) -> Any:
    """Return the ListParametersResult of `names` for the prefixes and depth (rclpy's rules)."""
    result = _ListParametersResult()
    recursive = not prefixes and depth == 0  # ListParameters DEPTH_RECURSIVE

    def shallow(name: str) -> bool:
        return name.count(PARAMETER_SEPARATOR) < depth

    for name in names:
        if not recursive and not (not prefixes and shallow(name)):
            if not any(
                name == prefix
                or (
                    name.startswith(prefix + PARAMETER_SEPARATOR)
                    and (depth == 0 or shallow(name[len(prefix) + 1:]))
                )
                for prefix in prefixes
            ):
                continue
        result.names.append(name)
        if PARAMETER_SEPARATOR in name:
            prefix = name[: name.rfind(PARAMETER_SEPARATOR)]
            if prefix not in result.prefixes:
                result.prefixes.append(prefix)
    return result


class ParameterService:
    """The six parameter services of one node."""

    def __init__(self, node: Any) -> None:
        self.node = node
        name = node.get_name()
        for srv_type, service, callback in (
            (DescribeParameters, 'describe_parameters', self._describe),
            (GetParameters, 'get_parameters', self._get),
            (GetParameterTypes, 'get_parameter_types', self._get_types),
            (ListParameters, 'list_parameters', self._list),
            (SetParameters, 'set_parameters', self._set),
            (SetParametersAtomically, 'set_parameters_atomically', self._set_atomically),
        ):
            node.create_service(
                srv_type, f'{name}/{service}', callback, qos_profile=parameters_qos()
            )

    def _describe(self, request: Any, response: Any) -> Any:
        try:
            response.descriptors = [
                descriptor_message(self.node.describe_parameter(n)) for n in request.names
            ]
        except ParameterNotDeclaredException:
            response.descriptors = []
        return response

    def _get(self, request: Any, response: Any) -> Any:
        try:
            response.values = [
                parameter_message(self.node.get_parameter(n)).value for n in request.names
            ]
        except (ParameterNotDeclaredException, ParameterUninitializedException):
            response.values = []
        return response

    def _get_types(self, request: Any, response: Any) -> Any:
        try:
            types = [int(self.node.get_parameter_type(n)) for n in request.names]
        except ParameterNotDeclaredException:
            types = []
        response.types = np.asarray(types, dtype=np.uint8)
        return response

    def _list(self, request: Any, response: Any) -> Any:
        response.result = self.node.list_parameters(list(request.prefixes), int(request.depth))
        return response

    def _set(self, request: Any, response: Any) -> Any:
        response.results = [self._set_atomically_result([p]) for p in request.parameters]
        return response

    def _set_atomically(self, request: Any, response: Any) -> Any:
        response.result = self._set_atomically_result(request.parameters)
        return response

    def _set_atomically_result(self, messages: list[Any]) -> Any:
        try:
            result = self.node.set_parameters_atomically(
                [parameter_from_message(m) for m in messages]
            )
        except ParameterNotDeclaredException as exc:
            result = SetParametersResult(False, str(exc))
        return _SetParametersResultMsg(successful=result.successful, reason=result.reason)
