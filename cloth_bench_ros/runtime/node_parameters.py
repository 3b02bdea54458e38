"""
The parameter API of the embedded Node (rclpy/node.py): declare, get, set, describe, list.

A mixin of runtime/node.py's Node, which holds the state it works on: `_parameters`,
`_descriptors`, `_overrides` (from the command line and parameter files), `_on_set_callbacks`
and the `/parameter_events` publisher.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence
import warnings

from cloth_bench_ros.runtime.parameter_errors import (
    InvalidParameterException,
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterAlreadyDeclaredException,
    ParameterNotDeclaredException,
    ParameterUninitializedException,
)
from cloth_bench_ros.runtime.parameter_service import list_parameters
from cloth_bench_ros.runtime.parameters import (
    FloatingPointRange,
    IntegerRange,
    Parameter,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from cloth_bench_ros.runtime.rosout import parameter_event

PARAM_REL_TOL = 1e-6  # rclpy Node.PARAM_REL_TOL: a double this close to an end is in range


def descriptor_result(
    parameter: Parameter, descriptor: ParameterDescriptor, check_read_only: bool = True
) -> SetParametersResult:
    """
    Return whether `descriptor` admits `parameter` (rclpy's _apply_descriptor).

    Checked in rclpy's order: read-only, type, then an integer or floating-point range.

    A declaration is checked without read-only (an override still sets a read-only parameter).
    """
    if check_read_only and descriptor.read_only:
        return SetParametersResult(
            False, f'Trying to set a read-only parameter: {parameter.name}.'
        )
    if not descriptor.dynamic_typing and parameter.type_ == ParameterType.NOT_SET:
        if check_read_only:  # a change, not a declaration by type
            return SetParametersResult(False, 'Static parameter cannot be undeclared')
    elif not descriptor.dynamic_typing and parameter.type_ != descriptor.type:
        return SetParametersResult(
            False,
            f"Wrong parameter type, expected 'Type.{ParameterType(descriptor.type).name}'"
            f" got 'Type.{parameter.type_.name}'",
        )
    if parameter.type_ == ParameterType.INTEGER and descriptor.integer_range:
        return _in_range(parameter, descriptor.integer_range[0])
    if parameter.type_ == ParameterType.DOUBLE and descriptor.floating_point_range:
        return _in_range(parameter, descriptor.floating_point_range[0])
    return SetParametersResult(True)


def _in_range(
    parameter: Parameter, limits: IntegerRange | FloatingPointRange
) -> SetParametersResult:
    """Check a range as rclpy's _apply_integer_range/_apply_floating_point_range: ends in, step."""
    low, high = sorted((limits.from_value, limits.to_value))
    value = parameter.value
    double = isinstance(limits, FloatingPointRange)
    if double and any(math.isclose(value, end, rel_tol=PARAM_REL_TOL) for end in (low, high)):
        return SetParametersResult(True)
    if value in (low, high):
        return SetParametersResult(True)
    if not low < value < high:
        return SetParametersResult(
            False,
            f'Parameter {parameter.name} out of range{" " if double else ". "}'
            f'Min: {low}, Max: {high}, value: {value}',
        )
    if limits.step and not double and (value - low) % limits.step:
        return SetParametersResult(
            False,
            f'The parameter value for {parameter.name} is not a valid step. Min: {low}, '
            f'max: {high}, value: {value}, step: {limits.step}',
        )
    if limits.step and double:
        steps = round((value - low) / limits.step)
        if not math.isclose(low + steps * limits.step, value, rel_tol=PARAM_REL_TOL):
            return SetParametersResult(
                False,
                f'The parameter value for {parameter.name} is not close enough to a valid '
                f'step. Min: {low}, max: {high}, value: {value}, step: {limits.step}',
            )
    return SetParametersResult(True)


class NodeParameters:
    """Node's parameter methods, with rclpy's checks, exceptions and parameter events."""

    _parameters: dict[str, Parameter]
    _descriptors: dict[str, ParameterDescriptor]
    _overrides: dict[str, Parameter]
    _on_set_callbacks: list[Callable[[list[Parameter]], SetParametersResult]]
    _parameter_events: Any
    _clock: Any

    def get_fully_qualified_name(self) -> str:
        raise NotImplementedError

    def declare_parameter(
        self,
        name: str,
        value: Any = None,
        descriptor: ParameterDescriptor | None = None,
        ignore_override: bool = False,
    ) -> Parameter:
        if not name:
            raise InvalidParameterException(name)
        descriptor = (
            dataclasses.replace(descriptor) if descriptor is not None else ParameterDescriptor()
        )
        if isinstance(value, ParameterType):
            if value == ParameterType.NOT_SET:
                raise ValueError(
                    f'Cannot declare parameter {{{name}}} as statically typed of type NOT_SET'
                )
            if descriptor.dynamic_typing:
                raise ValueError(
                    f'When declaring parameter {{{name}}} passing a descriptor with'
                    '`dynamic_typing=True` is not allowed when the parameter type is provided'
                )
            descriptor.type, value = int(value), None
        elif value is None and not descriptor.dynamic_typing:
            warnings.warn(  # rclpy (Jazzy): deprecated, declared with dynamic typing
                f"when declaring parameter named '{name}', declaring a parameter only providing "
                'its name is deprecated. You have to either:\n\t- Pass a name and a default '
                'value different to "PARAMETER NOT SET" (and optionally a descriptor).\n\t- Pass '
                'a name and a parameter type.\n\t- Pass a name and a descriptor with '
                '`dynamic_typing=True',
                stacklevel=2,
            )
            descriptor.dynamic_typing = True
        elif not descriptor.dynamic_typing:
            descriptor.type = int(ParameterType.from_parameter_value(value))
            if descriptor.type == ParameterType.NOT_SET:
                raise ValueError(
                    'Cannot declare a statically typed parameter with default value '
                    'of type PARAMETER_NOT_SET'
                )
        if not ignore_override and name in self._overrides:
            value = self._overrides[name].value
        parameter = Parameter(name, value=value)
        if name in self._parameters:
            raise ParameterAlreadyDeclaredException([name])
        if descriptor.dynamic_typing:
            descriptor.type = int(parameter.type_)
        elif parameter.type_ != ParameterType.NOT_SET and parameter.type_ != descriptor.type:
            raise InvalidParameterTypeException(parameter, ParameterType(descriptor.type).name)
        descriptor.name = name
        checked = descriptor_result(parameter, descriptor, check_read_only=False)
        if not checked.successful:  # out of the descriptor's range
            raise InvalidParameterValueException(name, parameter.value, checked.reason)
        for callback in self._on_set_callbacks:  # rclpy runs them on a declaration too
            result = callback([parameter])
            if not result.successful:
                raise InvalidParameterValueException(name, parameter.value, result.reason)
        self._parameters[name], self._descriptors[name] = parameter, descriptor
        self._publish_parameter_event(new=[parameter])
        return parameter

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter(self, name: str) -> Parameter:
        if name not in self._parameters:
            raise ParameterNotDeclaredException(name)
        parameter = self._parameters[name]
        if parameter.type_ == ParameterType.NOT_SET and not self._descriptors[name].dynamic_typing:
            raise ParameterUninitializedException(name)
        return parameter

    def add_on_set_parameters_callback(
        self, callback: Callable[[list[Parameter]], SetParametersResult]
    ) -> None:
        """Run `callback` before a change is applied; it may refuse it (rclpy: newest first)."""
        self._on_set_callbacks.insert(0, callback)

    def remove_on_set_parameters_callback(self, callback: Callable) -> None:
        self._on_set_callbacks.remove(callback)

    def set_parameters(self, parameter_list: list[Parameter]) -> list[SetParametersResult]:
        """Set each parameter on its own, as rclpy does: a result per parameter."""
        for parameter in parameter_list:
            if parameter.name not in self._parameters:
                raise ParameterNotDeclaredException(parameter.name)
        return [self.set_parameters_atomically([p]) for p in parameter_list]

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        """Set all or none: read-only, type and range checks, then the node's callbacks (rclpy)."""
        for parameter in parameter_list:
            if parameter.name not in self._parameters:
                raise ParameterNotDeclaredException(parameter.name)
            result = descriptor_result(parameter, self._descriptors[parameter.name])
            if not result.successful:
                return result
        for callback in self._on_set_callbacks:
            result = callback(parameter_list)
            if not result.successful:
                return result
        for parameter in parameter_list:
            self._parameters[parameter.name] = parameter
            if self._descriptors[parameter.name].dynamic_typing:
                self._descriptors[parameter.name].type = int(parameter.type_)
        self._publish_parameter_event(changed=parameter_list)
        return SetParametersResult(True)

    def _publish_parameter_event(
        self, new: Sequence[Parameter] = (), changed: Sequence[Parameter] = ()
    ) -> None:
        stamp = self._clock.now().to_msg()
        self._parameter_events.publish(
            parameter_event(self.get_fully_qualified_name(), stamp, new, changed)
        )

    def describe_parameter(self, name: str) -> ParameterDescriptor:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    def get_parameters(self, names: list[str]) -> list[Parameter]:
        return [self.get_parameter(name) for name in names]

    def get_parameter_type(self, name: str) -> ParameterType:
        if name not in self._parameters:
            raise ParameterNotDeclaredException(name)
        return self._parameters[name].type_

    def describe_parameters(self, names: list[str]) -> list[ParameterDescriptor]:
        return [self.describe_parameter(name) for name in names]

    def list_parameters(self, prefixes: list[str], depth: int) -> Any:
        """Return rcl_interfaces/msg/ListParametersResult of the declared parameters."""
        if not isinstance(prefixes, list) or not all(isinstance(p, str) for p in prefixes):
            raise TypeError('The prefixes argument must be a list of str')
        if not isinstance(depth, int) or depth < 0:
            raise ValueError('The depth must be an integer greater than or equal to zero')
        return list_parameters(list(self._parameters), prefixes, depth)
