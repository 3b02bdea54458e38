"""
The `--ros-args` command line as rcl parses it: parameters, parameter files, remap rules.

Follows rcl/src/rcl/arguments.c (flags, order, unknown arguments), rcl/src/rcl/remap.c (first
matching rule wins, node-specific rules, topic rules matched on fully qualified names) and
rcl/src/rcl/expand_topic_name.c. What the embedded runtime cannot honour (service remaps,
wildcards in a remap) is refused with one line rather than ignored.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import re
import sys

from cloth_bench_ros.runtime.parameters import (
    load_params_file,
    Overrides,
    parse_param_rule,
    RCLInvalidROSArgsError,
    UnknownROSArgsError,
)

_TOKEN = r'[A-Za-z_][A-Za-z0-9_]*'
_TOPIC = re.compile(
    rf'(~|~/{_TOKEN}(/{_TOKEN})*|/?({_TOKEN}|\{{node\}})(/({_TOKEN}|\{{node\}}))*|/)'
)
_FLAGS_WITH_VALUE = {'--log-level', '--log-file-name', '--log-config-file', '--enclave', '-e'}
_LOG_SWITCHES = {
    f'--{state}-{what}-logs'
    for state in ('enable', 'disable')
    for what in ('stdout', 'rosout', 'external-lib')
}


@dataclass
class RemapRule:
    """`[node:]match:=replacement`; match is `__ns`, `__node` or a topic name."""

    node: str | None
    match: str
    replacement: str


@dataclass
class RosArguments:
    """What one `--ros-args` command line sets."""

    overrides: Overrides = field(default_factory=Overrides)
    remaps: list[RemapRule] = field(default_factory=list)


def _remap_rule(text: str) -> RemapRule:
    bad = RCLInvalidROSArgsError(f"Couldn't parse remap rule: '-r {text}'")
    head, sep, replacement = text.partition(':=')
    if not sep:
        raise bad
    if head.startswith('rosservice://') or head.startswith('rostopic://'):
        if head.startswith('rosservice://'):
            raise RCLInvalidROSArgsError(
                f"remap rule '-r {text}': the embedded runtime has no services"
            )
        head = head[len('rostopic://'):]
    node, colon, match = head.rpartition(':')
    if colon and not re.fullmatch(_TOKEN, node):
        raise bad
    if '*' in match:
        raise RCLInvalidROSArgsError(
            f"remap rule '-r {text}': wildcards in remap rules are not supported"
        )
    if match in ('__node', '__name'):
        if not re.fullmatch(_TOKEN, replacement):
            raise bad
        match = '__node'
    elif match == '__ns':
        if not re.fullmatch(rf'/|(/{_TOKEN})+', replacement):
            raise bad
    elif not (_TOPIC.fullmatch(match) and _TOPIC.fullmatch(replacement)):
        raise bad
    return RemapRule(node or None, match, replacement)


def parse_ros_args(args: list[str] | None) -> RosArguments:
    """Every `--ros-args ... [--]` section of `args` (None: sys.argv, as rclpy.init), in order."""
    parsed = RosArguments()
    unknown: list[str] = []
    inside = False
    args = list(sys.argv if args is None else args)
    i = 0
    while i < len(args):
        arg = args[i]
        if not inside:
            inside = arg == '--ros-args'
            i += 1
            continue
        if arg == '--ros-args':
            i += 1
        elif arg == '--':
            inside = False
            i += 1
        elif arg in ('-p', '--param', '-r', '--remap', '--params-file') + tuple(_FLAGS_WITH_VALUE):
            if i + 1 >= len(args):
                raise RCLInvalidROSArgsError(f"Couldn't parse trailing {arg} flag")
            value = args[i + 1]
            if arg in ('-p', '--param'):
                parse_param_rule(value, parsed.overrides)
            elif arg in ('-r', '--remap'):
                parsed.remaps.append(_remap_rule(value))
            elif arg == '--params-file':
                load_params_file(value, parsed.overrides)
            i += 2
        elif arg in _LOG_SWITCHES:
            i += 1
        else:
            unknown.append(arg)
            i += 1
    if unknown:
        raise UnknownROSArgsError(f'Found unknown ROS arguments or parameters: {unknown}')
    return parsed


def expand_topic_name(name: str, node_name: str, namespace: str) -> str:
    """Return a topic name made fully qualified as rcl_expand_topic_name does."""
    name = name.replace('{node}', node_name)
    base = namespace.rstrip('/')
    if name == '~':
        return f'{base}/{node_name}'
    if name.startswith('~/'):
        return f'{base}/{node_name}/{name[2:]}'
    if name.startswith('/'):
        return name
    return f'{base}/{name}'


def _first(rules: list[RemapRule], match: str, node: str) -> RemapRule | None:
    return next((r for r in rules if r.match == match and r.node in (None, node)), None)


def remap_node_name(rules: list[RemapRule], node_name: str) -> str:
    """Return the name after the first `__node` rule for this node (rcl_remap_node_name)."""
    rule = _first(rules, '__node', node_name)
    return rule.replacement if rule else node_name


def remap_namespace(rules: list[RemapRule], node_name: str, namespace: str) -> str:
    """Return the namespace after the node's first `__ns` rule (rcl_remap_node_namespace)."""
    rule = _first(rules, '__ns', node_name)
    return rule.replacement if rule else namespace


def remap_topic_name(rules: list[RemapRule], topic: str, node_name: str, namespace: str) -> str:
    """Return a fully qualified topic after the first rule whose expanded match equals it."""
    for rule in rules:
        if rule.match in ('__node', '__ns') or rule.node not in (None, node_name):
            continue
        if expand_topic_name(rule.match, node_name, namespace) == topic:
            return expand_topic_name(rule.replacement, node_name, namespace)
    return topic


class NameValidationException(Exception):
    """rclpy.exceptions.NameValidationException: an invalid node name or namespace."""


class InvalidNodeNameException(NameValidationException):
    """A node name that is not letters, digits and '_' (not starting with a digit)."""


class InvalidNamespaceException(NameValidationException):
    """A namespace that is not '/' or '/'-separated name tokens."""


def validate_node_name(name: str) -> None:
    """rmw_validate_node_name's rule (rclpy raises InvalidNodeNameException)."""
    if not re.fullmatch(_TOKEN, name) or len(name) > 255:
        raise InvalidNodeNameException(
            f"Invalid node name: node name '{name}' must be letters, digits "
            "and '_', not starting with a digit"
        )


def validate_namespace(namespace: str) -> None:
    """rmw_validate_namespace's rule (rclpy raises InvalidNamespaceException)."""
    if not re.fullmatch(rf'/|(/{_TOKEN})+', namespace):
        raise InvalidNamespaceException(
            f"Invalid namespace: namespace '{namespace}' must be '/' or "
            "'/'-separated tokens of letters, digits and '_'"
        )
