"""
Parameters as rclpy handles them: ParameterType, Parameter, ParameterDescriptor, results.

Follows rclpy's parameter.py (types and values) and node.py's declare_parameter type checks;
rclpy's parameter exceptions are runtime/parameter_errors.py, parameter files and `-p` rules
runtime/params_file.py. Nothing here imports rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import enum
from typing import Any

# --- types (rclpy/parameter.py) ----------------------------------------------------------------


class ParameterType(enum.IntEnum):
    """rclpy.Parameter.Type: the values of rcl_interfaces/msg/ParameterType."""

    NOT_SET = 0
    BOOL = 1
    INTEGER = 2
    DOUBLE = 3
    STRING = 4
    BYTE_ARRAY = 5
    BOOL_ARRAY = 6
    INTEGER_ARRAY = 7
    DOUBLE_ARRAY = 8
    STRING_ARRAY = 9

    @classmethod
    def from_parameter_value(cls, value: Any) -> 'ParameterType':
        """Return the type rclpy infers from a Python value (an empty list is a BYTE_ARRAY)."""
        if value is None:
            return cls.NOT_SET
        for py_type, scalar in (
            (bool, cls.BOOL),
            (int, cls.INTEGER),
            (float, cls.DOUBLE),
            (str, cls.STRING),
        ):
            if isinstance(value, py_type):
                return scalar
        if isinstance(value, (list, tuple)):
            arrays: tuple[tuple[type, ParameterType], ...] = (
                (bytes, cls.BYTE_ARRAY),
                (bool, cls.BOOL_ARRAY),
                (int, cls.INTEGER_ARRAY),
                (float, cls.DOUBLE_ARRAY),
                (str, cls.STRING_ARRAY),
            )
            for element_type, array in arrays:
                if all(isinstance(v, element_type) for v in value):
                    return array
            raise TypeError(
                f"The given value is not a list of one of the allowed types '{value}'."
            )
        raise TypeError(f"The given value is not one of the allowed types '{value}'.")

    def check(self, value: Any) -> bool:
        """Return True if `value` is of this type, by rclpy's isinstance rules (bool is an int)."""
        scalar = {
            ParameterType.BOOL: bool,
            ParameterType.INTEGER: int,
            ParameterType.DOUBLE: float,
            ParameterType.STRING: str,
        }
        if self == ParameterType.NOT_SET:
            return value is None
        if self in scalar:
            return isinstance(value, scalar[self])
        element = {
            ParameterType.BYTE_ARRAY: bytes,
            ParameterType.BOOL_ARRAY: bool,
            ParameterType.INTEGER_ARRAY: int,
            ParameterType.DOUBLE_ARRAY: float,
            ParameterType.STRING_ARRAY: str,
        }[self]
        return isinstance(value, (list, tuple)) and all(isinstance(v, element) for v in value)


class Parameter:
    """rclpy.parameter.Parameter: a name, a type and a value that agree."""

    Type = ParameterType

    def __init__(self, name: str, type_: ParameterType | None = None, value: Any = None) -> None:
        if type_ is None:
            type_ = ParameterType.from_parameter_value(value)
        if not isinstance(type_, ParameterType):
            raise TypeError(f"type must be an instance of '{ParameterType!r}'")
        if not type_.check(value):
            raise ValueError(f"Type '{type_}' and value '{value}' do not agree")
        self._name, self._type_, self._value = name, type_, value

    @property
    def name(self) -> str:
        return self._name

    @property
    def type_(self) -> ParameterType:
        return self._type_

    @property
    def value(self) -> Any:
        return self._value

    def __repr__(self) -> str:
        return f'Parameter({self._name!r}, {self._type_.name}, value={self._value!r})'


@dataclass
class FloatingPointRange:
    """rcl_interfaces/msg/FloatingPointRange: [from_value, to_value], step 0 for any value."""

    from_value: float = 0.0
    to_value: float = 0.0
    step: float = 0.0


@dataclass
class IntegerRange:
    """rcl_interfaces/msg/IntegerRange: [from_value, to_value], step 0 for any value."""

    from_value: int = 0
    to_value: int = 0
    step: int = 0


@dataclass
class ParameterDescriptor:
    """rcl_interfaces/msg/ParameterDescriptor, the fields declare_parameter reads."""

    name: str = ''
    type: int = 0  # noqa: A003  (rcl_interfaces' field name)
    description: str = ''
    read_only: bool = False
    dynamic_typing: bool = False
    floating_point_range: list[FloatingPointRange] = field(default_factory=list)
    integer_range: list[IntegerRange] = field(default_factory=list)


@dataclass
class SetParametersResult:
    """rcl_interfaces/msg/SetParametersResult: whether a change was taken, and why not."""

    successful: bool = False
    reason: str = ''
