"""
Strictness cases run the same way under real rclpy and the embedded runtime; prints their outcomes.

`python test/conformance_cases.py` prints one JSON object: case name -> outcome (a value, or
`error: <class>` with rclpy's exception class). test_conformance.py runs it under each runtime
and compares. Written only against the API the nodes use (cloth_bench_ros.runtime), so the same
code runs on either runtime.
"""

from __future__ import annotations

import contextlib
import json
import sys
import time
from typing import Any, Callable, Iterator
import warnings

from cloth_bench_ros.runtime import (
    DescribeParameters,
    DiagnosticArray,
    DurabilityPolicy,
    EMBEDDED,
    FloatingPointRange,
    GetParameters,
    GetParameterTypes,
    HistoryPolicy,
    IntegerRange,
    ListParameters,
    Parameter,
    ParameterDescriptor,
    ParameterMsg,
    ParameterValue,
    PoseArray,
    QoSProfile,
    rclpy,
    ReliabilityPolicy,
    SetParameters,
    SetParametersAtomically,
    SetParametersResult,
    SingleThreadedExecutor,
)

# Exception classes compared by name, most specific first (rclpy's and the embedded runtime's).
_CLASSES = (
    'InvalidTopicNameException',
    'InvalidNodeNameException',
    'InvalidNamespaceException',
    'ParameterUninitializedException',
    'ParameterNotDeclaredException',
    'ParameterAlreadyDeclaredException',
    'InvalidParameterTypeException',
    'InvalidParameterValueException',
    'InvalidParameterException',
    'UnknownROSArgsError',
    'RCLError',
    'TypeError',
    'ValueError',
    'RuntimeError',
)
CASES: dict[str, Callable[[], Any]] = {}
# Cases run each in a process of its own: rcl configures logging once per process, so log levels
# set by earlier cases would leak into them (as they would into any later node of that process).
ISOLATED: list[str] = []


def case(name: str) -> Callable:
    def register(function: Callable[[], Any]) -> Callable[[], Any]:
        CASES[name] = function
        return function

    return register


def _error(exc: BaseException) -> str:
    names = [cls.__name__ for cls in type(exc).__mro__]
    return 'error: ' + next((n for n in _CLASSES if n in names), names[0])


class _Graph:
    """One context with one node, shut down on exit."""

    def __init__(self, args: list[str] | None = None, name: str = 'probe') -> None:
        self.context = rclpy.Context()
        rclpy.init(args=['prog', '--ros-args', *(args or [])], context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float, until: Callable[[], bool] = lambda: False) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            self.executor.spin_once(timeout_sec=0.01)

    def __enter__(self) -> '_Graph':
        return self

    def __exit__(self, *_: Any) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


# --- names: rcl_validate_topic_name, rcl_expand_topic_name, rmw_validate_full_topic_name ----

TOPIC_NAMES = [
    '1abc',
    '/a//b',
    '/a/',
    'a b',
    '',
    '~',
    '~/x',
    '~x',
    '{node}/x',
    '/{node}',
    'a/1b',
    '/_a',
    'a__b',
    '{bad}',
    '/a/~',
    'a/{node}',
    'a-b',
    'ns/{node}/x',
]

for _topic in TOPIC_NAMES:

    @case(f'topic name {_topic!r}')
    def _publisher_topic(topic: str = _topic) -> str:
        with _Graph(name='probe') as graph:
            return graph.node.create_publisher(PoseArray, topic, 10).topic_name


@case('subscription topic name 1abc')
def _subscription_topic() -> str:
    with _Graph() as graph:
        return graph.node.create_subscription(PoseArray, '1abc', lambda m: None, 10).topic_name


# --- the --ros-args command line: rcl's arguments.c --------------------------------------------

ROS_ARGS = [
    ['--log-level', 'bogus'],
    ['--log-level', 'DEBUG'],
    ['--log-level', 'debug'],
    ['--log-level', 'Warning'],
    ['--log-level', 'unset'],
    ['--log-level', 'probe:=warn'],
    ['--log-level', 'probe:=bogus'],
    ['--log-level', ':=warn'],
    ['--log-level', 'a.b:=info'],
    ['--log-level'],
    ['-r', 'rosservice://a:=b'],
    ['-r', 'rostopic://a:=b'],
    ['-r', 'probe:a:=b'],
    ['-r', '/a//b:=c'],
    ['-r', '1a:=b'],
    ['-r', 'a:=/b/'],
    ['-r', '~/a:=b'],
    ['-r', 'a/*:=b'],
    ['-r', 'no_separator'],
    ['-r', '__ns:=relative'],
    ['-p', 'name:='],
    ['-p', 'p:={a: 1}'],
    ['-p', 'p:=[1, a]'],
    ['--params-file', '/nonexistent/params.yaml'],
    ['--unknown-flag'],
    ['--log-file-name', 'x'],
    ['--enclave', '/x'],
    ['--enable-rosout-logs'],
    ['--disable-stdout-logs'],
]

for _args in ROS_ARGS:

    @case(f'arguments {" ".join(_args)}')
    def _arguments(args: list[str] = _args) -> str:
        with _Graph(args):
            return 'ok'


# --- one type per topic in a context (rmw refuses a second type for a topic name) ----------


@case('two types on one topic, one node')
def _two_types_one_node() -> str:
    with _Graph() as graph:
        graph.node.create_publisher(PoseArray, '/same', 10)
        graph.node.create_publisher(DiagnosticArray, '/same', 10)
        return 'ok'


@case('two types on one topic, subscription first, two nodes')
def _two_types_two_nodes() -> str:
    with _Graph() as graph:
        other = rclpy.create_node('other', context=graph.context)
        other.create_subscription(DiagnosticArray, '/same', lambda m: None, 10)
        try:
            graph.node.create_publisher(PoseArray, '/same', 10)
        finally:
            other.destroy_node()
        return 'ok'


@case('the same type on one topic twice')
def _same_type_twice() -> int:
    with _Graph() as graph:
        graph.node.create_publisher(PoseArray, '/same', 10)
        graph.node.create_subscription(PoseArray, '/same', lambda m: None, 10)
        return graph.node.count_publishers('/same')


# --- parameters: rclpy's declare_parameter ---------------------------------------------------


@case('declare_parameter without a default')
def _declare_without_default() -> list:
    with _Graph() as graph, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        declared = graph.node.declare_parameter('no_default')
        got = graph.node.get_parameter('no_default')
        return [
            declared.type_.name,
            got.value,
            graph.node.describe_parameter('no_default').dynamic_typing,
            sorted({w.category.__name__ for w in caught}),
        ]


@case('declare_parameter without a default, overridden')
def _declare_without_default_overridden() -> list:
    with _Graph(['-p', 'no_default:=3']) as graph, warnings.catch_warnings():
        warnings.simplefilter('ignore')
        declared = graph.node.declare_parameter('no_default')
        return [declared.type_.name, declared.value]


@case('declare_parameter with a type only, then get')
def _declare_type_only() -> Any:
    with _Graph() as graph:
        graph.node.declare_parameter('typed', Parameter.Type.DOUBLE)
        return graph.node.get_parameter('typed').value


@case('declare_parameter dynamic typing with no value')
def _declare_dynamic_none() -> Any:
    with _Graph() as graph:
        return graph.node.declare_parameter(
            'anything', None, ParameterDescriptor(dynamic_typing=True)
        ).value


@case('declare_parameter integer override for a double')
def _integer_for_double() -> Any:
    with _Graph(['-p', 'rate_hz:=1000']) as graph:
        return graph.node.declare_parameter('rate_hz', 100.0).value


@case('use_sim_time override not a bool')
def _use_sim_time_int() -> str:
    with _Graph(['-p', 'use_sim_time:=1']):
        return 'ok'


# --- changing parameters: rclpy's set_parameters, its checks and callbacks --------------------


def _results(results: list) -> list[bool]:
    return [r.successful for r in results]


@case('set_parameters on an undeclared parameter')
def _set_undeclared() -> Any:
    with _Graph() as graph:
        return _results(graph.node.set_parameters([Parameter('missing', value=1)]))


@case('set_parameters: another type, read-only, a good value')
def _set_checks() -> list:
    with _Graph() as graph:
        node = graph.node
        node.declare_parameter('rate', 1.0)
        node.declare_parameter('fixed', 'a', ParameterDescriptor(read_only=True))
        node.declare_parameter('free', 1, ParameterDescriptor(dynamic_typing=True))
        results = node.set_parameters(
            [
                Parameter('rate', value='fast'),
                Parameter('fixed', value='b'),
                Parameter('rate', value=2.0),
                Parameter('free', value='any'),
            ]
        )
        values = [node.get_parameter(n).value for n in ('rate', 'fixed', 'free')]
        return [_results(results), values]


@case('set_parameters_atomically with one bad value changes nothing')
def _set_atomically() -> list:
    with _Graph() as graph:
        node = graph.node
        node.declare_parameter('a', 1)
        node.declare_parameter('b', 1)
        result = node.set_parameters_atomically(
            [Parameter('a', value=2), Parameter('b', value='x')]
        )
        return [result.successful, node.get_parameter('a').value, node.get_parameter('b').value]


@case('a set-parameters callback refuses a declaration and a change')
def _callback_refuses() -> list:
    with _Graph() as graph:
        node = graph.node
        node.declare_parameter('kept', 1)
        node.add_on_set_parameters_callback(
            lambda ps: SetParametersResult(successful=all(p.value != 13 for p in ps), reason='13')
        )
        changed = _results(node.set_parameters([Parameter('kept', value=13)]))
        try:
            node.declare_parameter('unlucky', 13)
            declared = 'ok'
        except Exception as exc:  # noqa: B902 (the outcome is the class)
            declared = _error(exc)
        return [changed, node.get_parameter('kept').value, declared]


def _outcome(result: Any) -> list:
    return [result.successful, result.reason]


@case("a descriptor's range: ends, inside, outside, its step, and a declaration outside it")
def _descriptor_ranges() -> dict:
    with _Graph(['-p', 'far:=7', '-p', 'near:=1.0000001']) as graph:
        node = graph.node
        ints = ParameterDescriptor(integer_range=[IntegerRange(from_value=0, to_value=10, step=2)])
        floats = ParameterDescriptor(
            floating_point_range=[FloatingPointRange(from_value=1.0, to_value=2.5, step=0.0)]
        )
        node.declare_parameter('count', 4, ints)
        node.declare_parameter('ratio', 1.5, floats)
        node.declare_parameter('near', 2.0, floats)  # within rclpy's tolerance of an end
        set_ = {
            f'count {v}': _outcome(node.set_parameters([Parameter('count', value=v)])[0])
            for v in (0, 10, 6, 5, 12, -2)
        }
        set_.update({
            f'ratio {v}': _outcome(node.set_parameters([Parameter('ratio', value=v)])[0])
            for v in (1.0, 2.5, 2.0, 0.5, 1e9)
        })
        try:
            node.declare_parameter('far', 1, ints)
            declared = 'ok'
        except Exception as exc:  # noqa: B902 (the outcome is the class)
            declared = _error(exc)
        values = [node.get_parameter(n).value for n in ('count', 'ratio', 'near')]
        return {'set': set_, 'declared outside': declared, 'values': values}


@case('a read-only parameter: its override is taken, a change refused, atomically too')
def _read_only() -> list:
    with _Graph(['-p', 'fixed:=3']) as graph:
        node = graph.node
        node.declare_parameter('fixed', 1, ParameterDescriptor(read_only=True))
        node.declare_parameter('free', 1)
        one = node.set_parameters([Parameter('fixed', value=4), Parameter('free', value=5)])
        both = node.set_parameters_atomically(
            [Parameter('free', value=6), Parameter('fixed', value=4)]
        )
        values = [node.get_parameter(n).value for n in ('fixed', 'free')]
        return [[_outcome(r) for r in one], _outcome(both), values]


@case('a declared option is read-only and carries its range')
def _declared_option() -> list:
    from cloth_bench_ros.runtime import declare_option

    with _Graph(['-p', 'rate_hz:=1000']) as graph:
        node = graph.node
        rate = declare_option(node, 'rate_hz')
        nx = declare_option(node, 'grid_nx')
        described = node.describe_parameter('grid_nx')
        refused = node.set_parameters([Parameter('rate_hz', value=10.0)])[0]
        side = described.integer_range[0]
        return [rate, nx, described.read_only, [side.from_value, side.to_value],
                _outcome(refused), node.get_parameter('rate_hz').value]


@case('the trajectory publisher refuses changes on a running node')
def _node_refuses_changes() -> list:
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher

    with _Graph() as graph:
        node = TrajectoryPublisher(context=graph.context)
        try:
            refused = node.set_parameters(
                [Parameter('rate_hz', value='fast'), Parameter('rate_hz', value=1000.0)]
            )
            sim_time = node.set_parameters([Parameter('use_sim_time', value=False)])
            return [_results(refused), node.get_parameter('rate_hz').value, _results(sim_time)]
        finally:
            node.destroy_node()


# --- what every node publishes: /rosout (rcl) and /parameter_events (rclpy) -----------------

if EMBEDDED:
    from cloth_bench_ros.runtime.rosout import Log, ParameterEvent
else:
    from rcl_interfaces.msg import Log, ParameterEvent


def _heard(args: list[str], act: Callable[[Any], None], topic: str, msg_type: Any) -> list:
    """Return what a listener hears on `topic` from a node /ns/talker while `act(talker)` runs."""
    with _Graph(args, name='listener') as graph:
        heard: list = []
        sub = graph.node.create_subscription(msg_type, topic, heard.append, 100)
        talker = rclpy.create_node('talker', namespace='ns', context=graph.context)
        try:
            graph.spin_for(1.0, until=lambda: sub.get_publisher_count() >= 2)
            act(talker)
            graph.spin_for(0.5)
        finally:
            talker.destroy_node()
        return heard


def _rosout(args: list[str]) -> list:
    def talk(node: Any) -> None:  # one call site per severity: rclpy refuses a change of it
        node.get_logger().debug('d')
        node.get_logger().info('i')
        node.get_logger().warning('w')

    heard = _heard(args, talk, '/rosout', Log)
    return [[m.level, m.name, m.msg] for m in heard if m.name == 'ns.talker']


for _args in ([], ['--log-level', 'debug'], ['--log-level', 'ns.talker:=warn'],
              ['--disable-rosout-logs']):

    @case(f'rosout with {" ".join(_args) or "the defaults"}')
    def _rosout_case(args: list[str] = _args) -> list:
        return _rosout(args)

    ISOLATED.append(f'rosout with {" ".join(_args) or "the defaults"}')


@case('parameter events of declarations and a change')
def _parameter_events() -> list:
    def change(node: Any) -> None:
        node.declare_parameter('a', 1)
        node.declare_parameter('names', ['x', 'y'])
        node.set_parameters([Parameter('a', value=2)])

    heard = _heard([], change, '/parameter_events', ParameterEvent)
    return [
        [
            [(p.name, p.value.type) for p in m.new_parameters],
            [(p.name, p.value.type, p.value.integer_value) for p in m.changed_parameters],
            list(m.new_parameters[0].value.string_array_value) if m.new_parameters else [],
        ]
        for m in heard
        if m.node == '/ns/talker'
    ]


# --- services: every node's parameter services (rclpy/parameter_service.py), and one's own -----


def _call(graph: _Graph, srv_type: Any, name: str, request: Any) -> Any:
    """Call a service from the graph's node; 'not ready' or 'no answer' if it does not come."""
    client = graph.node.create_client(srv_type, name)
    try:
        if not client.wait_for_service(timeout_sec=3.0):
            return 'not ready'
        future = client.call_async(request)
        graph.executor.spin_until_future_complete(future, timeout_sec=3.0)
        return future.result() if future.done() else 'no answer'
    finally:
        graph.node.destroy_client(client)


def _value(value: Any) -> list:
    """Return a ParameterValue as [type, the field that type uses]."""
    fields = [None, 'bool_value', 'integer_value', 'double_value', 'string_value',
              'byte_array_value', 'bool_array_value', 'integer_array_value',
              'double_array_value', 'string_array_value']
    field = fields[value.type]
    data = getattr(value, field) if field else None
    if field == 'byte_array_value':
        data = [b[0] if isinstance(b, bytes) else int(b) for b in data]
    elif field and field.endswith('_array_value'):
        data = [x.item() if hasattr(x, 'item') else x for x in data]
    return [int(value.type), data]


def _plain(value: Any) -> Any:
    """Return a parameter value as JSON holds it (rclpy keeps numeric arrays as array.array)."""
    return value if isinstance(value, (str, bool, int, float)) else list(value)


@contextlib.contextmanager
def _talker(graph: _Graph) -> Iterator[Any]:
    """Yield a node /ns/talker with parameters of several kinds, spun by the graph's executor."""
    talker = rclpy.create_node('talker', namespace='ns', context=graph.context)
    talker.declare_parameter('rate_hz', 100.0)
    talker.declare_parameter('mesh.rows', 9)
    talker.declare_parameter('mesh.cols', 12)
    talker.declare_parameter('mesh.solver.iterations', 5)
    talker.declare_parameter('names', ['a', 'b'])
    talker.declare_parameter('gains', [1.5, 2.5])
    read_only = ParameterDescriptor(read_only=True, description='d')
    talker.declare_parameter('engine', 'mujoco', read_only)
    talker.declare_parameter('anything', 1, ParameterDescriptor(dynamic_typing=True))
    graph.executor.add_node(talker)
    try:
        yield talker
    finally:
        talker.destroy_node()


def _msg(name: str, **value: Any) -> Any:
    return ParameterMsg(name=name, value=ParameterValue(**value))


@case('parameter services: list, get, types, describe')
def _parameter_services_read() -> dict:
    with _Graph(name='caller') as graph:
        with _talker(graph):
            names = ['rate_hz', 'mesh.rows', 'names', 'gains', 'engine', 'use_sim_time']
            listed = _call(graph, ListParameters, '/ns/talker/list_parameters',
                           ListParameters.Request())
            got = _call(graph, GetParameters, '/ns/talker/get_parameters',
                        GetParameters.Request(names=names))
            types = _call(graph, GetParameterTypes, '/ns/talker/get_parameter_types',
                          GetParameterTypes.Request(names=names))
            described = _call(graph, DescribeParameters,
                              '/ns/talker/describe_parameters',
                              DescribeParameters.Request(names=['engine', 'anything', 'gains']))
            return {
                'list': [sorted(listed.result.names), sorted(listed.result.prefixes)],
                'get': [_value(v) for v in got.values],
                'types': [int(x) for x in types.types],
                'describe': [
                    [d.name, int(d.type), d.description, d.read_only, d.dynamic_typing]
                    for d in described.descriptors
                ],
            }


@case('parameter services: an undeclared name empties the answer')
def _parameter_services_undeclared() -> list:
    with _Graph(name='caller') as graph:
        with _talker(graph):
            names = ['rate_hz', 'nope']
            got = _call(graph, GetParameters, '/ns/talker/get_parameters',
                        GetParameters.Request(names=names))
            types = _call(graph, GetParameterTypes, '/ns/talker/get_parameter_types',
                          GetParameterTypes.Request(names=names))
            described = _call(graph, DescribeParameters,
                              '/ns/talker/describe_parameters',
                              DescribeParameters.Request(names=names))
            return [len(got.values), len(types.types), len(described.descriptors)]


for _prefixes, _depth in (([], 1), ([], 2), (['mesh'], 0), (['mesh'], 1), (['mesh', 'rate_hz'], 2),
                          (['mes'], 0)):

    @case(f'parameter services: list prefixes {_prefixes} depth {_depth}')
    def _parameter_services_list(prefixes: list = _prefixes, depth: int = _depth) -> list:
        with _Graph(name='caller') as graph:
            with _talker(graph):
                listed = _call(graph, ListParameters, '/ns/talker/list_parameters',
                               ListParameters.Request(prefixes=prefixes, depth=depth))
                return [sorted(listed.result.names), sorted(listed.result.prefixes)]


@case('parameter services: set and set atomically')
def _parameter_services_set() -> dict:
    with _Graph(name='caller') as graph:
        with _talker(graph) as talker:
            results = _call(graph, SetParameters, '/ns/talker/set_parameters',
                            SetParameters.Request(parameters=[
                                _msg('rate_hz', type=4, string_value='fast'),
                                _msg('rate_hz', type=3, double_value=250.0),
                                _msg('mesh.rows', type=3, double_value=9.5),
                                _msg('engine', type=4, string_value='bullet'),
                                _msg('nope', type=2, integer_value=1),
                                _msg('anything', type=4, string_value='now a string'),
                                _msg('names', type=9, string_array_value=['c']),
                            ]))
            atomic_bad = _call(graph, SetParametersAtomically,
                               '/ns/talker/set_parameters_atomically',
                               SetParametersAtomically.Request(parameters=[
                                   _msg('mesh.cols', type=2, integer_value=20),
                                   _msg('mesh.rows', type=4, string_value='x'),
                               ]))
            atomic_good = _call(graph, SetParametersAtomically,
                                '/ns/talker/set_parameters_atomically',
                                SetParametersAtomically.Request(parameters=[
                                    _msg('mesh.cols', type=2, integer_value=20),
                                    _msg('gains', type=8, double_array_value=[0.5]),
                                ]))
            names = ['rate_hz', 'mesh.rows', 'mesh.cols', 'engine', 'anything', 'names', 'gains']
            return {
                'set': [r.successful for r in results.results],
                'reasons given': [bool(r.reason) for r in results.results],
                'atomically, one bad': atomic_bad.result.successful,
                'atomically, all good': atomic_good.result.successful,
                'values': [_plain(talker.get_parameter(n).value) for n in names],
            }


@case('the trajectory publisher refuses a change through its set_parameters service')
def _node_refuses_through_service() -> list:
    from cloth_bench_ros.nodes.trajectory_publisher import TrajectoryPublisher

    with _Graph(name='caller') as graph:
        node = TrajectoryPublisher(context=graph.context)
        graph.executor.add_node(node)
        try:
            name = node.get_fully_qualified_name() + '/set_parameters'
            results = _call(graph, SetParameters, name, SetParameters.Request(parameters=[
                _msg('rate_hz', type=3, double_value=10.0),
                _msg('use_sim_time', type=1, bool_value=False),
            ]))
            return [[r.successful for r in results.results], node.get_parameter('rate_hz').value]
        finally:
            node.destroy_node()


@case('a service of its own: names, remaps, readiness and a call')
def _own_service() -> dict:
    args = ['-r', 'rosservice://renamed:=/elsewhere', '-r', 'rostopic://plain:=/moved']
    with _Graph(args, name='server') as graph:
        def answer(request: Any, response: Any) -> Any:
            response.types = [len(n) for n in request.names]
            return response

        services = [
            graph.node.create_service(GetParameterTypes, name, answer)
            for name in ('~/private', 'renamed', 'plain')
        ]
        missing = graph.node.create_client(GetParameterTypes, '/nobody/here')
        try:
            reply = _call(graph, GetParameterTypes, '/elsewhere',
                          GetParameterTypes.Request(names=['ab', 'cde']))
            return {
                'names': [[s.srv_name, s.service_name] for s in services],
                'ready without a server': [missing.service_is_ready(),
                                           missing.wait_for_service(timeout_sec=0.2)],
                'reply': [int(x) for x in reply.types],
            }
        finally:
            graph.node.destroy_client(missing)


# --- QoS: matching and what a reader keeps ---------------------------------------------------


def _qos(
    reliability: Any = ReliabilityPolicy.RELIABLE,
    durability: Any = DurabilityPolicy.VOLATILE,
    depth: int = 10,
    history: Any = HistoryPolicy.KEEP_LAST,
) -> Any:
    return QoSProfile(depth=depth, reliability=reliability, durability=durability, history=history)


def _delivery(writer: Any, reader: Any, published_before_reader: bool = False) -> dict:
    """Five messages through one writer/reader pair: matched counts and what the reader got."""
    with _Graph() as graph:
        got: list[int] = []
        pub = graph.node.create_publisher(PoseArray, '/qos', writer)

        def send() -> None:
            for i in range(5):
                msg = PoseArray()
                msg.header.frame_id = str(i)
                pub.publish(msg)

        if published_before_reader:
            send()
        sub = graph.node.create_subscription(
            PoseArray, '/qos', lambda m: got.append(int(m.header.frame_id)), reader
        )
        graph.spin_for(1.0, until=lambda: pub.get_subscription_count() > 0)
        if published_before_reader:
            graph.spin_for(0.2)  # let a late joiner's history arrive (DDS)
        matched = [pub.get_subscription_count(), sub.get_publisher_count()]
        if not published_before_reader:
            send()
        graph.spin_for(1.0, until=lambda: len(got) == 5)
        graph.spin_for(0.2)
        in_graph = graph.node.count_subscribers('/qos')
        if reader.history == HistoryPolicy.KEEP_LAST and reader.depth == 1:
            # How many of a burst a keep-last-1 reader sees depends on when its executor takes
            # them, under either runtime; what DDS promises is the newest one, in order.
            newest = {'last': got[-1] if got else None, 'in order': got == sorted(set(got))}
            return {'matched': matched, 'received': newest, 'in graph': in_graph}
        return {'matched': matched, 'received': got, 'in graph': in_graph}


QOS_CASES = {
    'best effort writer, reliable reader': (_qos(ReliabilityPolicy.BEST_EFFORT), _qos(), False),
    'reliable writer, best effort reader': (_qos(), _qos(ReliabilityPolicy.BEST_EFFORT), False),
    'volatile writer, transient local reader': (
        _qos(),
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL),
        False,
    ),
    'transient local writer, volatile reader': (
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL),
        _qos(),
        False,
    ),
    'keep last 1 reader, five sent before a spin': (_qos(), _qos(depth=1), False),
    'keep all reader of depth 1': (
        _qos(history=HistoryPolicy.KEEP_ALL),
        _qos(history=HistoryPolicy.KEEP_ALL, depth=1),
        False,
    ),
    'late transient local reader, writer depth 3': (
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL, depth=3),
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL),
        True,
    ),
    'late transient local reader of depth 1': (
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL, depth=3),
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL, depth=1),
        True,
    ),
    'late volatile reader of a transient local writer': (
        _qos(durability=DurabilityPolicy.TRANSIENT_LOCAL, depth=3),
        _qos(),
        True,
    ),
}

for _label, (_writer, _reader, _late) in QOS_CASES.items():

    @case(f'qos {_label}')
    def _qos_case(writer: Any = _writer, reader: Any = _reader, late: bool = _late) -> dict:
        return _delivery(writer, reader, late)


def run(selected: list[str] | None = None) -> dict[str, Any]:
    """Return the outcomes of the cases named in `selected`, or of all but the isolated ones."""
    outcomes: dict[str, Any] = {'_runtime': 'embedded' if EMBEDDED else 'rclpy'}
    for name, function in CASES.items():
        if (selected and name not in selected) or (not selected and name in ISOLATED):
            continue
        try:
            outcomes[name] = function()
        except Exception as exc:  # noqa: B902 (every outcome is recorded, errors included)
            outcomes[name] = _error(exc)
    return outcomes


if __name__ == '__main__':
    print(json.dumps(run(sys.argv[1:] or None)))
