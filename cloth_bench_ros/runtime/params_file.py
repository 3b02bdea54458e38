"""
Parameter files and `-p` rules as rcl reads them: scalar typing, node keys, overrides in order.

Follows rcl_yaml_param_parser/src/parse.c (node-name keys, scalar typing, what a file may hold),
rcl/src/rcl/arguments.c (`-p`, `--params-file` in command-line order) and src/rclpy/node.cpp
(matching a node's name against the file's keys). Nothing here imports rclpy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from pathlib import Path
import re
from typing import Any

from cloth_bench_ros.runtime.parameter_errors import RCLInvalidROSArgsError
from cloth_bench_ros.runtime.parameters import Parameter, ParameterType
import yaml

PARAMS_KEY = 'ros__parameters'
_STR_TAG = 'tag:yaml.org,2002:str'


# --- rcl's scalar typing (parse.c get_value) and node-name keys (parse.c _validate_name) -------

_BOOL_TRUE = {'Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON'}
_BOOL_FALSE = {'N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF'}
_STRTOLL = re.compile(r'\s*[+-]?(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)')
_STRTOD = re.compile(
    r'\s*[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|0[xX]([0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)'
    r'([pP][+-]?\d+)?|inf|infinity|nan(\([0-9a-zA-Z_]*\))?)',
    re.IGNORECASE,
)
_SPECIAL_FLOATS = {
    f'{sign}.{word}' for sign in ('', '+', '-') for word in ('inf', 'Inf', 'INF')
} | {'.nan', '.NaN', '.NAN'}
_NAME_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')


def rcl_scalar(text: str, quoted: bool, str_tag: bool) -> Any:
    """Return the value rcl gives a YAML scalar: bool, int (strtoll), float (strtod), else str."""
    if str_tag or quoted:
        return text
    if text in _BOOL_TRUE or text in _BOOL_FALSE:
        return text in _BOOL_TRUE
    if _STRTOLL.fullmatch(text):
        value = (
            int(text.strip(), 0)
            if not re.fullmatch(r'\s*[+-]?0[0-7]+', text)
            else int(text.strip(), 8)
        )
        if -(2**63) <= value < 2**63:
            return value
    if text in _SPECIAL_FLOATS:
        return (
            math.nan
            if 'nan' in text.lower()
            else (-math.inf if text.startswith('-') else math.inf)
        )
    if _STRTOD.fullmatch(text):
        body = text.strip()
        stripped = body.lstrip('+-')
        number = float.fromhex(body) if stripped[:2].lower() == '0x' else float(body)
        overflow = math.isinf(number) and not stripped.lower().startswith('inf')
        underflow = number == 0.0 and any(
            c in '123456789'
            for c in re.split(r'[eEpP]', stripped)[0][2 * (stripped[:2].lower() == '0x'):]
        )
        if not (overflow or underflow):  # strtod sets ERANGE: rcl then keeps the text
            return number
    return text


def validate_node_key(key: str) -> str | None:
    """None if rcl accepts `key` as a parameter file's node name, else why not."""
    if key in ('/**', '/*'):
        return None
    namespace, slash, node = key.rpartition('/')
    if slash:
        tokens = ('/' + namespace if not namespace.startswith('/') else namespace).split('/')[1:]
        if '' in tokens and tokens != ['']:
            return 'contains repeated forward slash'
        for token in tokens:
            if token in ('*', '**') or token == '':
                continue
            if not _NAME_TOKEN.fullmatch(token):
                return f"namespace token '{token}' is not a name ([A-Za-z_][A-Za-z0-9_]*)"
    if node in ('*', '**'):
        return None
    if not node:
        return 'node name must not be empty'
    if not _NAME_TOKEN.fullmatch(node):
        return (
            f"node name '{node}' is not valid: a node name is letters, digits and '_', not"
            " starting with a digit, and a wildcard is only a whole '*' or '**' token"
        )
    return None


# --- parameter files and -p rules -------------------------------------------------------------


class ParamsFileError(RCLInvalidROSArgsError):
    """A parameter file rcl would refuse; str() is one line naming the file and the key."""


@dataclass
class Overrides:
    """
    Parameter overrides as rcl_params_t holds them: node keys in order of first appearance.

    A key seen again (a later file, a `-p` rule under `/**`) keeps its place and its values are
    overwritten; rclpy then applies every key that matches a node in this order, so a later key
    wins over an earlier one whatever their wildcards.
    """

    entries: dict[str, dict[str, Any]] = field(default_factory=dict)

    def set(self, node_key: str, name: str, value: Any) -> None:  # noqa: A003  (a store's verb)
        self.entries.setdefault(node_key, {})[name] = value

    def for_node(self, fully_qualified_name: str) -> dict[str, Parameter]:
        """Return the overrides rclpy's Node.get_parameters hands a node (src/rclpy/node.cpp)."""
        out: dict[str, Parameter] = {}
        for key, params in self.entries.items():
            pattern = ('/' + key if not key.startswith('/') else key).replace('/*', r'(/\w+)')
            if re.fullmatch(pattern, fully_qualified_name):
                out.update({name: Parameter(name, value=value) for name, value in params.items()})
        return out


def _events_tree(events: list, path: str) -> list:
    """Return each YAML document's tree of mappings, sequences and scalars; aliases refused."""
    stack: list[list] = []
    roots: list = []
    for event in events:
        node: Any = None
        if isinstance(event, yaml.AliasEvent):
            raise ParamsFileError(
                f'params file {path}: line {event.start_mark.line + 1}: aliases are not supported'
            )
        if isinstance(event, yaml.ScalarEvent):
            node = ('scalar', event)
        elif isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            stack.append(
                ['map' if isinstance(event, yaml.MappingStartEvent) else 'seq', event, []]
            )
            continue
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            kind, start, items = stack.pop()
            node = (kind, start, items)
        else:
            continue
        if stack:
            stack[-1][2].append(node)
        else:
            roots.append(node)
    return roots


def _line(event: Any) -> int:
    return event.start_mark.line + 1


def _value(node: Any, where: str) -> Any:
    """Return a parameter value: a scalar, or a sequence of scalars of one type (parse_value)."""
    if node[0] == 'scalar':
        event = node[1]
        if event.style not in ("'", '"') and event.value == '':
            raise ParamsFileError(f'{where}: no value at line {_line(event)}')
        return rcl_scalar(event.value, event.style in ("'", '"'), event.tag == _STR_TAG)
    if node[0] == 'seq':
        values = []
        for item in node[2]:
            if item[0] != 'scalar':
                raise ParamsFileError(
                    f'{where}: a sequence may only hold scalars (line {_line(item[1])})'
                )
            values.append(_value(item, where))
        kinds = {ParameterType.from_parameter_value([v]) for v in values}
        if len(kinds) > 1:
            raise ParamsFileError(
                f'{where}: sequence should be of same type (line {_line(node[1])})'
            )
        return values or None  # an empty sequence sets no value: the parameter stays NOT_SET
    raise ParamsFileError(f'{where}: a mapping is not a parameter value (line {_line(node[1])})')


def _node_entries(node: Any, prefix: str, path: str, out: Overrides) -> None:
    if node[0] != 'map':
        raise ParamsFileError(
            f'params file {path}: line {_line(node[1])}: cannot have a value before {PARAMS_KEY}'
        )
    items = node[2]
    for key_node, child in zip(items[::2], items[1::2]):
        if key_node[0] != 'scalar':
            raise ParamsFileError(
                f'params file {path}: line {_line(key_node[1])}: a key must be a scalar'
            )
        key = key_node[1].value
        if key.startswith(PARAMS_KEY):
            if not prefix:
                raise ParamsFileError(
                    f'params file {path}: line {_line(key_node[1])}: there are no node '
                    f'names before {PARAMS_KEY}'
                )
            problem = validate_node_key(prefix)
            if problem:
                raise ParamsFileError(f"params file {path}: key '{prefix}': {problem}")
            out.entries.setdefault(prefix, {})
            _parameters(child, prefix, '', path, out)
        else:
            _node_entries(child, key if not prefix else prefix.rstrip('/') + '/' + key, path, out)


def _parameters(node: Any, node_key: str, param_prefix: str, path: str, out: Overrides) -> None:
    if node[0] != 'map':
        raise ParamsFileError(
            f"params file {path}: key '{node_key}': {PARAMS_KEY} must be a mapping"
        )
    items = node[2]
    for key_node, child in zip(items[::2], items[1::2]):
        name = param_prefix + key_node[1].value
        if child[0] == 'map':
            _parameters(child, node_key, name + '.', path, out)
            continue
        where = f"params file {path}: key '{node_key}' parameter '{name}'"
        out.set(node_key, name, _value(child, where))


def load_params_file(path: str | Path, into: Overrides | None = None) -> Overrides:
    """Return a ROS 2 parameter file parsed and checked as rcl parses it, merged into `into`."""
    out = into if into is not None else Overrides()
    try:
        text = Path(path).read_text()
        events = list(yaml.parse(text, Loader=yaml.SafeLoader))
    except OSError as exc:
        raise ParamsFileError(f'params file {path}: {exc.strerror or exc}') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        raise ParamsFileError(
            f'params file {path}: not YAML' + (f' (line {mark.line + 1})' if mark else '')
        ) from None
    for root in _events_tree(events, str(path)):  # rcl reads every document of the file
        _node_entries(root, '', str(path), out)
    return out


def parse_param_rule(rule: str, into: Overrides) -> None:
    """Parse a `-p [node:]name:=value` rule as rcl does; the node key is `/**` by default."""
    head, sep, text = rule.partition(':=')
    node_key, colon, name = head.rpartition(':')
    node_key = node_key if colon else '/**'
    if not sep or not name or not text or (colon and not _NAME_TOKEN.fullmatch(node_key)):
        raise RCLInvalidROSArgsError(f"Couldn't parse parameter override rule: '-p {rule}'")
    try:
        (root,) = _events_tree(list(yaml.parse(text, Loader=yaml.SafeLoader)), '-p')
        into.set(node_key, name, _value(root, f'-p {rule}'))
    except (ValueError, yaml.YAMLError, ParamsFileError, TypeError):
        raise RCLInvalidROSArgsError(
            f"Couldn't parse parameter override rule: '-p {rule}'"
        ) from None
