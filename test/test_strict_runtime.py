"""
The embedded runtime is as strict as rcl and rclpy: each test states the rule and its source.

Sources read (GitHub): ros2/rcl @ c19dab5 (rcl_yaml_param_parser/src/parse.c and its
test/test_parse_yaml.cpp with test/wildcards*.yaml; rcl/src/rcl/arguments.c, remap.c, timer.c),
ros2/rclpy @ ba72a01 (rclpy/node.py, parameter.py, exceptions.py, time_source.py, publisher.py,
src/rclpy/node.cpp). No real ROS 2 runs here: the expectations are taken from those sources.
"""

import math
import os
import subprocess
import sys

from cloth_bench_ros.runtime import declare_float, is_user_error, steady_clock
from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime.embedded import (
    InvalidParameterException,
    InvalidParameterTypeException,
    Node,
    Parameter,
    ParameterAlreadyDeclaredException,
    ParameterDescriptor,
    ParameterNotDeclaredException,
    ParameterType,
    ParameterUninitializedException,
    RCLInvalidROSArgsError,
    ReliabilityPolicy,
    SingleThreadedExecutor,
    Time,
    UnknownROSArgsError,
)
from cloth_bench_ros.runtime.messages import Clock, PoseArray, String
from cloth_bench_ros.runtime.params_file import load_params_file, ParamsFileError, rcl_scalar
import pytest


@pytest.fixture
def context():
    ctx = rclpy.Context()
    yield ctx
    ctx.shutdown()


def _params_file(tmp_path, text, name='p.yaml'):
    path = tmp_path / name
    path.write_text(text)
    return path


# --- parameter files: rcl's node-name keys ----------------------------------------------------

ACCEPTED_KEYS = [
    '/**',
    '/*',
    '/**/some_node',
    '/*/some_node',
    '/foo/**',
    '/foo/*',
    '/foo/**/bar/node',
    '/foo/*/bar',
    'some_node',
    'ns/some_node',
    '/',
]


@pytest.mark.parametrize('key', ACCEPTED_KEYS)
def test_wildcard_keys_that_rcl_accepts(tmp_path, key):
    """As rcl's parse.c _validate_name: `*` and `**` as whole tokens."""
    nested = key == '/'  # root_ns.yaml: "/" then the node name one level down
    text = (
        f"'{key}':\n  my_node:\n    ros__parameters:\n      id: 10\n"
        if nested
        else f"'{key}':\n  ros__parameters:\n    id: 10\n"
    )
    overrides = load_params_file(_params_file(tmp_path, text))
    assert list(overrides.entries.values()) == [{'id': 10}]


PARTIAL_WILDCARDS = [
    '/foo**',
    '/**foo',
    '/f**oo',
    '/foo*',
    '/*foo',
    '/f*oo',
    '/**/node**',
    '/**/**node',
    '/**/n**ode',
    '/**/*node',
    '/**/node*',
    '/**/n*ode',
    '/**/simulator*',
]


@pytest.mark.parametrize('key', PARTIAL_WILDCARDS)
def test_partial_wildcards_are_refused_with_one_line_naming_file_and_key(tmp_path, key):
    """Rcl test_parse_yaml.cpp wildcards_partial_01..12 expect rcl_parse_yaml_file to fail."""
    path = _params_file(tmp_path, f"'{key}':\n  ros__parameters:\n    id: 10\n")
    with pytest.raises(ParamsFileError) as err:
        load_params_file(path)
    message = str(err.value)
    assert '\n' not in message and str(path) in message and f"'{key}'" in message


@pytest.mark.parametrize(
    'text',
    [
        '/foo:\n  /*:\n    ros__parameters:\n      id: 10\n',  # wildcards_node_slash.yaml
        'ns//node:\n  ros__parameters:\n    id: 10\n',  # empty_name_in_ns.yaml
        # params_with_no_node.yaml
        'node:\n  ros__parameters:\n    name: x\nros__parameters:\n  id: 10\n',
        'ns:\n  node:\n    ros__parameters:\n      id:\n',  # no_value1.yaml
        'node:\n  ros__parameters:\n    - driver: front\n',  # seq_map1.yaml
        'node:\n  ros__parameters:\n    name: &FL x\n    spec: *FL\n',  # no_alias_support.yaml
        'node:\n  ros__parameters:\n    mixed: [1, a]\n',  # parse_value: same type
        '/**:\n  rate_hz: 100.0\n',  # value before ros__parameters
        '1node:\n  ros__parameters:\n    id: 1\n',  # rmw_validate_node_name
    ],
)
def test_structures_rcl_refuses(tmp_path, text):
    """Rcl test_parse_yaml.cpp: these files make rcl_parse_yaml_file return false."""
    with pytest.raises(ParamsFileError, match='params file'):
        load_params_file(_params_file(tmp_path, text))


def test_scalars_are_typed_as_rcl_types_them_not_as_yaml_does(tmp_path):
    """As rcl's parse.c get_value: bool words, strtoll, strtod, else string; quotes keep text."""
    assert rcl_scalar('1000', False, False) == 1000 and isinstance(
        rcl_scalar('1000', False, False), int
    )
    assert rcl_scalar('1000.0', False, False) == 1000.0
    assert rcl_scalar('1e3', False, False) == 1000.0  # PyYAML's safe_load gives the string '1e3'
    assert rcl_scalar('010', False, False) == 8 and rcl_scalar('0x10', False, False) == 16
    assert rcl_scalar('08', False, False) == 8.0  # strtoll stops at 8; strtod reads it
    assert rcl_scalar('yes', False, False) is True and rcl_scalar('Off', False, False) is False
    assert rcl_scalar('null', False, False) == 'null' and rcl_scalar('~', False, False) == '~'
    assert math.isinf(rcl_scalar('-.inf', False, False)) and math.isnan(
        rcl_scalar('.nan', False, False)
    )
    assert rcl_scalar('1e999', False, False) == '1e999'  # strtod overflows (ERANGE): text
    assert rcl_scalar('5', True, False) == '5' and rcl_scalar('5', False, True) == '5'
    overrides = load_params_file(
        _params_file(
            tmp_path,
            "n:\n  ros__parameters:\n    a: !!str 5\n    b: '7'\n"
            '    c: 1e3\n    d: [1, 2]\n    g:\n      h: true\n',
        )
    )
    assert overrides.entries['n'] == {'a': '5', 'b': '7', 'c': 1000.0, 'd': [1, 2], 'g.h': True}


# --- overrides: rclpy's matching and order ----------------------------------------------------


def test_keys_match_as_rclpy_matches_them(tmp_path, context):
    """As rclpy's node.cpp: '/' prepended, then "/*" and "/**" as patterns, full match."""
    path = _params_file(
        tmp_path,
        '/*/n:\n  ros__parameters:\n    one_token: 1\n'
        '/**/n:\n  ros__parameters:\n    any_tokens: 1\n'
        'n:\n  ros__parameters:\n    root_only: 1\n'
        '/a/*:\n  ros__parameters:\n    any_node_in_a: 1\n',
    )
    rclpy.init(args=['prog', '--ros-args', '--params-file', str(path)], context=context)
    names = {}
    for ns in ('/', '/a', '/a/b'):
        node = Node('n', namespace=ns, context=context, use_global_arguments=True)
        names[ns] = {
            k
            for k in ('one_token', 'any_tokens', 'root_only', 'any_node_in_a')
            if node.declare_parameter(k, 0).value == 1
        }
    assert names == {
        '/': {'any_tokens', 'root_only'},
        '/a': {'one_token', 'any_tokens', 'any_node_in_a'},
        '/a/b': {'any_tokens'},
    }


def test_a_later_key_wins_and_a_key_keeps_the_place_it_first_appeared(tmp_path, context):
    """
    As rcl's parse.c find_node and rclpy's node.cpp: parameter entries in order, last wins.

    find_node keeps one entry per key in order of first appearance (over all files and -p rules,
    arguments.c); rclpy applies matching entries in that order, the last one winning.
    """
    first = _params_file(
        tmp_path,
        "/**:\n  ros__parameters:\n    bag: a\n/**/recorder:\n  ros__parameters:\n    bag: ''\n",
        'first.yaml',
    )
    second = _params_file(
        tmp_path,
        '/**:\n  ros__parameters:\n    bag: from_launch\n'
        '/cloth_bench/recorder:\n  ros__parameters:\n    topic: t\n',
        'second.yaml',
    )
    rclpy.init(
        args=[
            'prog',
            '--ros-args',
            '--params-file',
            str(first),
            '--params-file',
            str(second),
            '-p',
            'bag:=from_cli',
            '-p',
            'rate:=2',
        ],
        context=context,
    )
    node = Node('recorder', namespace='cloth_bench', context=context)
    assert node.declare_parameter('bag', '').value == ''  # /**/recorder comes after /**: it wins
    assert node.declare_parameter('topic', '').value == 't'
    assert node.declare_parameter('rate', 0).value == 2
    other = Node('evaluator', namespace='cloth_bench', context=context)
    assert (
        other.declare_parameter('bag', '').value == 'from_cli'
    )  # the -p rule overwrote /** in place


def test_constructor_overrides_come_last(tmp_path, context):
    """Rclpy node.py: parameter_overrides update the overrides read from the arguments."""
    rclpy.init(args=['prog', '--ros-args', '-p', 'seed:=1'], context=context)
    node = Node('n', context=context, parameter_overrides=[Parameter('seed', value=5)])
    assert node.declare_parameter('seed', 0).value == 5


# --- parameter types: rclpy's declare_parameter ----------------------------------------------


def test_an_integer_for_a_double_is_refused(context):
    """Rclpy node.py _apply_descriptor: 'Wrong parameter type' -> InvalidParameterTypeException."""
    rclpy.init(args=['prog', '--ros-args', '-p', 'rate_hz:=1000'], context=context)
    node = Node('n', context=context)
    with pytest.raises(InvalidParameterTypeException, match="expecting type 'DOUBLE'"):
        node.declare_parameter('rate_hz', 100.0)
    assert not isinstance(
        InvalidParameterTypeException(Parameter('x', value=1), 'DOUBLE'), ValueError
    )


def test_declare_float_takes_an_integer_and_refuses_a_string(context):
    """Dynamic typing (rclpy node.py) accepts any type; declare_float keeps numbers as float."""
    rclpy.init(
        args=['prog', '--ros-args', '-p', 'rate_hz:=1000', '-p', 'rate_factor:=fast'],
        context=context,
    )
    node = Node('n', context=context)
    assert declare_float(node, 'rate_hz', 100.0) == 1000.0
    with pytest.raises(ValueError, match='rate_factor'):
        declare_float(node, 'rate_factor', 1.0)


def test_declared_types_undeclared_and_uninitialised(context):
    """As rclpy's node.py: static type from the default, and its declaration errors."""
    rclpy.init(args=[], context=context)
    node = Node('n', context=context)
    assert node.declare_parameter('engines', ['mujoco']).type_ == ParameterType.STRING_ARRAY
    assert Parameter('empty', value=[]).type_ == ParameterType.BYTE_ARRAY  # as rclpy infers it
    with pytest.raises(ParameterAlreadyDeclaredException):
        node.declare_parameter('engines', ['x'])
    with pytest.raises(ParameterNotDeclaredException):
        node.get_parameter('missing')
    node.declare_parameter('typed', ParameterType.DOUBLE)
    with pytest.raises(ParameterUninitializedException):
        node.get_parameter('typed')
    with pytest.warns(UserWarning, match='only providing its name is deprecated'):
        declared = node.declare_parameter('no_default')  # Jazzy: dynamic typing, a warning
    assert declared.type_ == ParameterType.NOT_SET
    assert node.get_parameter('no_default').value is None
    assert (
        node.declare_parameter('anything', None, ParameterDescriptor(dynamic_typing=True)).value
        is None
    )
    with pytest.raises(InvalidParameterException):  # rclpy/validate_parameter_name.py
        node.declare_parameter('', 1)


def test_use_sim_time_must_be_a_bool(context):
    """Rclpy time_source.py declares use_sim_time False: a non-bool override is a type error."""
    rclpy.init(args=['prog', '--ros-args', '-p', 'use_sim_time:=1'], context=context)
    with pytest.raises(InvalidParameterTypeException, match='use_sim_time'):
        Node('n', context=context)


# --- time: clock, /clock QoS, timers ----------------------------------------------------------


def _sim_node(context, name='n'):
    return Node(name, context=context, parameter_overrides=[Parameter('use_sim_time', value=True)])


def _publish_clock(context, seconds):
    owner = Node('clock_owner', context=context)
    pub = owner.create_publisher(Clock, '/clock', 10)
    pub.publish(Clock(clock=Time(seconds=seconds).to_msg()))
    owner.destroy_node()  # its message is queued for the followers already


def test_clock_reads_zero_before_the_first_clock_message(context):
    """Rclpy time_source.py: 'Zero time is a special value that means time is uninitialized'."""
    rclpy.init(args=[], context=context)
    node = _sim_node(context)
    assert node.get_clock().now().nanoseconds == 0
    assert Node('wall', context=context).get_clock().now().nanoseconds > 1e18


def test_clock_subscription_is_depth_1_best_effort(context):
    """Rclpy time_source.py: QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)."""
    rclpy.init(args=[], context=context)
    node = _sim_node(context)
    (sub,) = [s for s in context.subscriptions['/clock'] if s.node is node]
    assert sub.qos.depth == 1 and sub.qos.reliability == ReliabilityPolicy.BEST_EFFORT


def test_timers_run_on_sim_time_under_use_sim_time(context):
    """Rclpy node.py create_timer uses the node's clock; rcl timer.c skips missed periods."""
    rclpy.init(args=[], context=context)
    node = _sim_node(context)
    ticks = []
    timer = node.create_timer(1.0, lambda: ticks.append(node.get_clock().now().nanoseconds))
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(node)
    for _ in range(5):
        ex.spin_once(timeout_sec=0.01)  # wall time passes, sim time does not
    assert ticks == []
    _publish_clock(context, 3.5)
    for _ in range(5):
        ex.spin_once(timeout_sec=0.01)
    assert ticks == [3_500_000_000]  # due at 1 s; 2 s and 3 s were missed and are skipped
    assert timer.time_until_next_call() == 500_000_000
    steady = []
    node.create_timer(0.001, lambda: steady.append(1), clock=steady_clock())
    for _ in range(3):
        ex.spin_once(timeout_sec=0.05)
    assert steady, 'a timer on a steady clock fires on the wall clock even under use_sim_time'


# --- remaps and arguments ---------------------------------------------------------------------


def test_remaps_are_applied_as_rcl_applies_them(context):
    """As rcl's remap.c: first matching rule, node rules for that node only, names expanded."""
    rclpy.init(
        args=[
            'prog',
            '--ros-args',
            '-r',
            'targets:=/elsewhere/targets',
            '-r',
            'b:cloud:=~/mine',
            '-r',
            '__ns:=/ns',
            '-r',
            '__ns:=/ignored',
            '-r',
            'a:__node:=renamed',
        ],
        context=context,
    )
    a, b = Node('a', context=context), Node('b', namespace='other', context=context)
    assert (a.get_name(), a.get_namespace(), b.get_namespace()) == ('renamed', '/ns', '/ns')
    assert a.create_publisher(PoseArray, 'targets', 10).topic_name == '/elsewhere/targets'
    assert a.resolve_topic_name('cloud') == '/ns/cloud'
    assert b.resolve_topic_name('cloud') == '/ns/b/mine'
    assert b.resolve_topic_name('cloud', only_expand=True) == '/ns/cloud'


@pytest.mark.parametrize(
    'args, error',
    [
        (['-r', '/a//b:=c'], RCLInvalidROSArgsError),
        (['--log-level', 'bogus'], RCLInvalidROSArgsError),
        (['--log-level', ':=warn'], RCLInvalidROSArgsError),
        (['-r', '/a/*:=/b'], RCLInvalidROSArgsError),
        (['-r', 'no_separator'], RCLInvalidROSArgsError),
        (['-r', '__ns:=relative'], RCLInvalidROSArgsError),
        (
            ['-p', 'engine_params:={mass: 0.4}'],
            RCLInvalidROSArgsError,
        ),  # parse_value_events: no mappings
        (['-p', 'name:='], RCLInvalidROSArgsError),
        (['--unknown-flag'], UnknownROSArgsError),
    ],
)
def test_arguments_rcl_refuses_are_refused(context, args, error):
    """As rcl's arguments.c: invalid rules are refused; rclpy raises on unknown ROS args."""
    with pytest.raises(error):
        rclpy.init(args=['prog', '--ros-args', *args], context=context)


def test_publishing_a_message_of_another_type_raises_type_error(context):
    """Rclpy publisher.py publish: 'Expected {msg_type}, got {type(msg)}' TypeError."""
    rclpy.init(args=[], context=context)
    pub = Node('n', context=context).create_publisher(PoseArray, 'targets', 10)
    with pytest.raises(TypeError, match='Expected'):
        pub.publish(String(data='x'))
    pub.publish(PoseArray())


# --- the nodes: one line and exit status 2, under either runtime ------------------------------


def test_rclpy_exception_classes_count_as_user_errors():
    """Check that nodes/common.py matches rclpy's exception classes by name."""
    base = type('ParameterException', (Exception,), {})
    assert is_user_error(type('InvalidParameterTypeException', (base,), {})())
    assert is_user_error(type('RCLInvalidROSArgsError', (RuntimeError,), {})())
    assert not is_user_error(RuntimeError('bug'))


@pytest.mark.parametrize(
    'args, expected',
    [
        (['-p', 'rate_hz:=fast'], 'rate_hz'),
        (['--params-file', '{bad}'], "'/**/simulator*'"),
        (['-p', 'primitive:=3'], 'primitive'),
    ],
)
def test_a_node_with_a_bad_argument_prints_one_line_and_exits_2(tmp_path, args, expected):
    """Check that a user error is one line and exit 2, for rcl/rclpy's errors too."""
    bad = _params_file(tmp_path, '/**/simulator*:\n  ros__parameters:\n    seed: 1\n')
    args = [a.replace('{bad}', str(bad)) for a in args]
    env = {**os.environ, 'CLOTH_BENCH_EMBEDDED': '1'}
    proc = subprocess.run(
        [sys.executable, '-m', 'cloth_bench_ros.nodes.trajectory_publisher', '--ros-args', *args],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0] and 'Traceback' not in proc.stderr


def test_the_readme_rate_hz_1000_works(context):
    """`-p rate_hz:=1000` is an INTEGER under rcl; the nodes declare it so that it is accepted."""
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher

    rclpy.init(args=['prog', '--ros-args', '-p', 'rate_hz:=1000'], context=context)
    node = TrajectoryPublisher(context=context)
    assert node.targets.rate_hz == 1000.0


def test_the_recorders_wall_clock_replay_runs_under_use_sim_time(context):
    """Check that its timer is on a steady clock (on the sim clock it would never fire)."""
    from pathlib import Path

    from cloth_bench_ros.nodes.recorder import Recorder

    bag = Path(__file__).resolve().parents[1] / 'bags' / 'towel_dynamic'
    rclpy.init(
        args=[
            'prog',
            '--ros-args',
            '-p',
            'use_sim_time:=true',
            '-p',
            'clock:=wall',
            '-p',
            'rate_factor:=50',
            '-p',
            f'bag:={bag}',
        ],
        context=context,
    )
    recorder = Recorder(context=context)
    ex = SingleThreadedExecutor(context=context)
    ex.add_node(recorder)
    for _ in range(2000):
        if recorder.done:
            break
        ex.spin_once(timeout_sec=0.01)
    assert recorder.done and recorder.published == len(
        list(recorder.bag.raw_messages([recorder.topic]))
    )
    assert recorder.get_clock().now().nanoseconds == 0  # no /clock: sim time never started
