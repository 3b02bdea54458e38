"""
runtime/arguments.py: the `--ros-args` command line and names as rcl parses and checks them.

The expectations are rcl's documented behaviour (arguments.c, remap.c, expand_topic_name.c,
validate_topic_name.c); test_real_ros.py compares the same rules with real rclpy where it runs.
"""

from __future__ import annotations

from cloth_bench_ros.errors import is_user_error
from cloth_bench_ros.runtime.arguments import (
    expand_topic_name,
    InvalidNamespaceException,
    InvalidNodeNameException,
    InvalidTopicNameException,
    parse_ros_args,
    remap_namespace,
    remap_node_name,
    remap_topic_name,
    validate_full_topic_name,
    validate_namespace,
    validate_node_name,
    validate_topic_name,
)
from cloth_bench_ros.runtime.parameter_errors import RCLInvalidROSArgsError, UnknownROSArgsError
import pytest


def test_only_the_ros_args_sections_are_read_in_order(tmp_path):
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    rate_hz: 50.0\n    seed: 3\n')
    args = parse_ros_args([
        'prog', '-p', 'ignored:=1', '--ros-args', '-p', 'rate_hz:=1000', '--params-file',
        str(params), '-r', '__node:=sim', '--', 'not_ros', '--ros-args', '--log-level', 'debug',
        '--disable-rosout-logs',
    ])  # fmt: skip
    # the file comes after the -p rule: its value wins, as rcl applies them in order
    assert args.overrides.entries == {'/**': {'rate_hz': 50.0, 'seed': 3}}
    assert [(r.match, r.replacement) for r in args.remaps] == [('__node', 'sim')]
    assert args.log_levels == {'': 10} and args.rosout is False


def test_an_integer_given_for_a_double_stays_an_integer_as_rcl_types_it():
    args = parse_ros_args(['--ros-args', '-p', 'rate_hz:=1000', '-p', 'name:="1000"'])
    values = args.overrides.entries['/**']
    assert values['rate_hz'] == 1000 and isinstance(values['rate_hz'], int)
    assert values['name'] == '1000'


@pytest.mark.parametrize(
    'argv, error',
    [
        (['--ros-args', '-p'], RCLInvalidROSArgsError),
        (['--ros-args', '-p', 'no_value'], RCLInvalidROSArgsError),
        (['--ros-args', '-r', '/a/*:=/b'], RCLInvalidROSArgsError),
        (['--ros-args', '--log-level', 'loud'], RCLInvalidROSArgsError),
        (['--ros-args', '--unknown-flag'], UnknownROSArgsError),
    ],
)
def test_a_bad_argument_is_refused_as_the_users_error(argv, error):
    with pytest.raises(error) as caught:
        parse_ros_args(argv)
    assert is_user_error(caught.value)  # one line and exit status 2 in a node's main


def test_topic_names_expand_and_remap_as_rcl_does():
    assert expand_topic_name('~/state', 'sim', '/cloth_bench') == '/cloth_bench/sim/state'
    assert expand_topic_name('{node}/x', 'sim', '/ns') == '/ns/sim/x'
    assert expand_topic_name('/abs', 'sim', '/ns') == '/abs'
    rules = parse_ros_args([
        '--ros-args', '-r', 'other:state:=/elsewhere', '-r', 'state:=/moved', '-r', 'state:=/late',
        '-r', 'sim:__ns:=/renamed', '-r', '__node:=simulator',
    ]).remaps  # fmt: skip
    assert remap_topic_name(rules, '/ns/state', 'sim', '/ns') == '/moved'  # the first match wins
    assert remap_topic_name(rules, '/ns/other', 'sim', '/ns') == '/ns/other'
    assert remap_namespace(rules, 'sim', '/ns') == '/renamed'
    assert remap_namespace(rules, 'recorder', '/ns') == '/ns'
    assert remap_node_name(rules, 'sim') == 'simulator'


def test_an_unknown_substitution_is_a_value_error_as_in_rclpy():
    with pytest.raises(ValueError, match='unknown substitution'):
        expand_topic_name('/a/{robot}', 'sim', '/ns')


@pytest.mark.parametrize(
    'check, name, error',
    [
        (validate_topic_name, 'a//b', InvalidTopicNameException),
        (validate_topic_name, '1abc', InvalidTopicNameException),
        (validate_topic_name, 'a{b', InvalidTopicNameException),
        (validate_full_topic_name, 'relative', InvalidTopicNameException),
        (validate_node_name, '9lives', InvalidNodeNameException),
        (validate_namespace, 'no_slash', InvalidNamespaceException),
    ],
)
def test_invalid_names_are_refused(check, name, error):
    with pytest.raises(error):
        check(name)


def test_valid_names_pass():
    validate_topic_name('~/cloud_{node}')
    validate_full_topic_name('/cloth_bench/real/cloud')
    validate_node_name('simulator_1')
    validate_namespace('/')
    validate_namespace('/cloth_bench/a')
