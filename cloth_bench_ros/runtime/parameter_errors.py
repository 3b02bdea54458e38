"""
rclpy's parameter and argument exceptions, as rclpy/exceptions.py and _rclpy name them.

Same names and messages as rclpy's, and like them no ValueErrors: the node mains report them as
the user's input by class name (cloth_bench_ros.errors.RCLPY_USER_ERRORS), in rclpy and here.
"""

from __future__ import annotations

from typing import Any, TYPE_CHECKING

if TYPE_CHECKING:
    from cloth_bench_ros.runtime.parameters import Parameter


class ParameterException(Exception):
    """Base exception for parameter-related errors."""

    def __init__(self, error_msg: str, parameters: Any) -> None:
        Exception.__init__(self, f'{error_msg}: {parameters}')


class ParameterNotDeclaredException(ParameterException):
    """An undeclared parameter was read."""

    def __init__(self, parameters: Any) -> None:
        ParameterException.__init__(self, 'Invalid access to undeclared parameter(s)', parameters)


class ParameterAlreadyDeclaredException(ParameterException):
    """A parameter was declared twice."""

    def __init__(self, parameters: Any) -> None:
        ParameterException.__init__(self, 'Parameter(s) already declared', parameters)


class InvalidParameterException(ParameterException):
    """A parameter name rclpy refuses (validate_parameter_name: an empty one)."""

    def __init__(self, parameter_name: str) -> None:
        ParameterException.__init__(self, 'Invalid parameter name', parameter_name)


class InvalidParameterTypeException(ParameterException):
    """An override's type is not the declared type."""

    def __init__(self, desired_parameter: Parameter, expected_type: str) -> None:
        ParameterException.__init__(
            self,
            f"Trying to set parameter '{desired_parameter.name}' to '{desired_parameter.value}'"
            f" of type '{desired_parameter.type_.name}', expecting type '{expected_type}'",
            desired_parameter.name,
        )


class ParameterUninitializedException(ParameterException):
    """A statically typed parameter without a value was read."""

    def __init__(self, parameter_name: str) -> None:
        ParameterException.__init__(
            self, f"The parameter '{parameter_name}' is not initialized", parameter_name
        )


class InvalidParameterValueException(ParameterException):
    """A value a set-parameters callback refused while the parameter was declared."""

    def __init__(self, parameter: str, value: Any, reason: str) -> None:
        Exception.__init__(
            self, f'Invalid parameter value ({value}) for parameter. Reason: {reason}', parameter
        )


class RCLError(RuntimeError):
    """rclpy's _rclpy.RCLError."""


class RCLInvalidROSArgsError(RCLError):
    """A malformed --ros-args argument (rcl: RCL_RET_INVALID_ROS_ARGS)."""


class UnknownROSArgsError(RCLError):
    """A --ros-args argument rcl does not know."""
