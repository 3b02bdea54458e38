"""
The `--ros-args` command line as rcl parses it: parameters, parameter files, remap rules.

Follows rcl/src/rcl/arguments.c (flags, order, unknown arguments), rcl/src/rcl/remap.c (first
matching rule wins, node-specific rules, topic rules matched on fully qualified names) and
rcl/src/rcl/expand_topic_name.c and validate_topic_name.c. A service remap is accepted (the
embedded runtime has no services for it to apply to); wildcards in a remap are refused, as in rcl.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import re
import sys

from cloth_bench_ros.runtime.parameter_errors import RCLInvalidROSArgsError, UnknownROSArgsError
from cloth_bench_ros.runtime.params_file import load_params_file, Overrides, parse_param_rule

_TOKEN = r'[A-Za-z_][A-Za-z0-9_]*'
_TOPIC = re.compile(
    rf'(~|~/{_TOKEN}(/{_TOKEN})*|/?({_TOKEN}|\{{node\}})(/({_TOKEN}|\{{node\}}))*|/)'
)
_FLAGS_WITH_VALUE = {'--log-level', '--log-file-name', '--log-config-file', '--enclave', '-e'}
_LOG_SEVERITIES = {'UNSET': 0, 'DEBUG': 10, 'INFO': 20, 'WARN': 30, 'ERROR': 40, 'FATAL': 50}
_LOG_SWITCHES = {
    f'--{state}-{what}-logs'
    for state in ('enable', 'disable')
    for what in ('stdout', 'rosout', 'external-lib')
}


@dataclass
class RemapRule:
    """`[node:][rostopic://|rosservice://]match:=replacement`; match: `__ns`, `__node`, a name."""

    node: str | None
    match: str
    replacement: str
    applies_to: str = 'any'  # 'topic' or 'service' with the URL prefix, else both


@dataclass
class RosArguments:
    """What one `--ros-args` command line sets."""

    overrides: Overrides = field(default_factory=Overrides)
    remaps: list[RemapRule] = field(default_factory=list)
    log_levels: dict[str, int] = field(default_factory=dict)  # logger ('' for all) -> level
    rosout: bool = True  # --disable-rosout-logs: no /rosout publisher


def _log_level(text: str, levels: dict[str, int]) -> None:
    """`--log-level [logger:=]severity` as rcl's arguments.c parses it (severity in any case)."""
    name, sep, severity = text.rpartition(':=')
    if sep and not name:
        raise RCLInvalidROSArgsError(
            f"Couldn't parse log level: '--log-level {text}'. "
            'Error: Argument has an invalid logger item that name is empty'
        )
    if severity.upper() not in _LOG_SEVERITIES:
        raise RCLInvalidROSArgsError(
            f"Couldn't parse log level: '--log-level {text}'. "
            'Error: Argument does not use a valid severity level'
        )
    levels[name] = _LOG_SEVERITIES[severity.upper()]


def _remap_rule(text: str) -> RemapRule:
    bad = RCLInvalidROSArgsError(f"Couldn't parse remap rule: '-r {text}'")
    head, sep, replacement = text.partition(':=')
    if not sep:
        raise bad
    parts = re.fullmatch(rf'(?:({_TOKEN}):(?!//))?(?:(rostopic|rosservice)://)?(.*)', head)
    if parts is None:
        raise bad
    node, scheme, match = parts.groups()
    applies_to = {'rostopic': 'topic', 'rosservice': 'service', None: 'any'}[scheme]
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
    return RemapRule(node or None, match, replacement, applies_to)


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
            elif arg == '--log-level':
                _log_level(value, parsed.log_levels)
            i += 2
        elif arg in _LOG_SWITCHES:
            if arg.endswith('-rosout-logs'):
                parsed.rosout = arg.startswith('--enable')
            i += 1
        else:
            unknown.append(arg)
            i += 1
    if unknown:
        raise UnknownROSArgsError(f'Found unknown ROS arguments or parameters: {unknown}')
    return parsed


def expand_topic_name(name: str, node_name: str, namespace: str) -> str:
    """Return a topic name made fully qualified as rcl_expand_topic_name does."""
    base = namespace.rstrip('/')
    if name.startswith('~'):
        name = f'{base}/{node_name}' + name[1:]

    def substitute(match: re.Match) -> str:
        key = match.group(1)
        if key == 'node':
            return node_name
        if key in ('ns', 'namespace'):
            return base
        # rclpy raises a ValueError here too (test/conformance_cases.py: topic name '{bad}')
        raise ValueError(f"topic name '{name}' is invalid: unknown substitution: {{{key}}}")

    name = re.sub(r'\{([^{}]*)\}', substitute, name)
    return name if name.startswith('/') else f'{base}/{name}'


class NameValidationException(Exception):
    """rclpy.exceptions.NameValidationException: an invalid node name, namespace or topic."""


class InvalidTopicNameException(NameValidationException):
    """A topic name rcl_validate_topic_name or rmw_validate_full_topic_name refuses."""

    def __init__(self, name: str, reason: str, index: int) -> None:
        caret = ' ' * index + '^'
        super().__init__(f"Invalid topic name: topic name {reason}:\n  '{name}'\n   {caret}")


def _topic_name_problem(name: str, extra: str) -> tuple[str, int] | None:
    """Return (why, where) the first rule a topic name breaks, chars `extra` allowed too."""
    if not name:
        return 'must not be empty string', 0
    if name.endswith('/') and name != '/':
        return 'must not end with a forward slash', len(name) - 1
    allowed = set(extra) | {'_', '/'}
    shown = ', '.join(f"'{c}'" for c in ('_', *extra)) if extra else "'_'"
    for index, char in enumerate(name):
        if not (char.isascii() and char.isalnum()) and char not in allowed:
            return f'must not contain characters other than alphanumerics, {shown}', index
    if '~' in name[1:]:
        return "must not have tilde '~' unless it is the first character", name.index('~', 1)
    if '//' in name:
        return "must not contain repeated '/'", name.index('//') + 1
    for match in re.finditer(r'(?:^|/)(\d)', name):
        return 'token must not start with a number', match.start(1)
    return None


def validate_topic_name(name: str) -> None:
    """rcl_validate_topic_name's rules for a name as given (rclpy: InvalidTopicNameException)."""
    problem = _topic_name_problem(name, '~{}')
    if problem is None and name.count('{') != name.count('}'):
        problem = 'must not have unmatched curly braces', name.find('{')
    if problem is not None:
        raise InvalidTopicNameException(name, *problem)


def validate_full_topic_name(name: str) -> None:
    """rmw_validate_full_topic_name's rules for an expanded name (absolute, tokens only)."""
    problem = _topic_name_problem(name, '')
    if problem is None and not name.startswith('/'):
        problem = 'must be absolute, it must lead with a forward slash', 0
    if problem is not None:
        raise InvalidTopicNameException(name, *problem)


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


def remap_topic_name(
    rules: list[RemapRule], topic: str, node_name: str, namespace: str, kind: str = 'topic'
) -> str:
    """Return a full topic (or service) name after the first rule that matches it, expanded."""
    for rule in rules:
        if rule.match in ('__node', '__ns') or rule.node not in (None, node_name):
            continue
        if rule.applies_to not in ('any', kind):
            continue
        if expand_topic_name(rule.match, node_name, namespace) == topic:
            return expand_topic_name(rule.replacement, node_name, namespace)
    return topic


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
