"""
An embedded stand-in for the subset of rclpy that the nodes use.

Messages travel over the context's transport (runtime/transport.py): intra-process by default,
or DDS (runtime/dds/: Cyclone DDS speaking ROS 2's wire protocol) between processes. In-process it
composes nodes as a component container with intra-process communication would, and runs their
callbacks deterministically: messages are delivered in the order they were
published (one FIFO for the whole context), timers fire on the node's clock (runtime/clock.py),
and a node with use_sim_time follows /clock. What it provides (and nothing more; docs/runtimes.md,
"Without ROS 2", lists it in full):

- rclpy.init(args, domain_id=, transport=), ok(), shutdown(), spin(node),
  spin_once(node, timeout_sec)
- graph queries: Node.get_publishers_info_by_topic, get_subscriptions_info_by_topic,
  get_node_names_and_namespaces; Subscription.get_publisher_count
- rclpy.node.Node(name, namespace=, parameter_overrides=, context=, cli_args=): create_publisher,
  create_subscription, create_timer, destroy_timer, declare_parameter, get_parameter,
  has_parameter, get_logger, get_clock, get_name, get_namespace, count_subscribers,
  count_publishers, destroy_node; parameters with rclpy's types and checks (runtime/parameters.py)
- Publisher.publish (TypeError for another message type) / get_subscription_count; Timer.cancel;
  Clock.now(); Time(nanoseconds=), Time.from_msg, .to_msg(), .nanoseconds
- rclpy.qos: QoSProfile(depth=, reliability=, durability=, history=) and the policy enums;
  TRANSIENT_LOCAL publishers hand their last `depth` messages to late subscribers
- rclpy.executors.SingleThreadedExecutor: add_node, remove_node, spin, spin_once, shutdown,
  and spin_until_idle() (returns once no message is queued and no timer is armed)
- rclpy.serialization.serialize_message / deserialize_message (CDR through rosbags)
- the --ros-args command line as rcl parses it: -p, --params-file, -r remaps (runtime/arguments.py)

QoS as DDS applies it, on either transport: incompatible writers and readers do not match, a
keep-last reader keeps its newest `depth` messages, a keep-all reader loses nothing.
"""

from __future__ import annotations

from collections import deque
import dataclasses
import logging
from typing import Any, Callable
import warnings

from cloth_bench_ros.data import messages as cdr
from cloth_bench_ros.runtime import messages
from cloth_bench_ros.runtime.arguments import (
    expand_topic_name,
    parse_ros_args,
    remap_namespace,
    remap_node_name,
    remap_topic_name,
    RosArguments,
    validate_full_topic_name,
    validate_namespace,
    validate_node_name,
    validate_topic_name,
)
from cloth_bench_ros.runtime.clock import (
    Clock,
    ClockType,
    Time,
    Timer,
)  # noqa: F401 (rclpy's names)
from cloth_bench_ros.runtime.parameters import (  # noqa: F401 (re-exported as rclpy's names)
    InvalidParameterException,
    InvalidParameterTypeException,
    InvalidParameterValueException,
    load_params_file,
    Parameter,
    ParameterAlreadyDeclaredException,
    ParameterDescriptor,
    ParameterException,
    ParameterNotDeclaredException,
    ParameterType,
    ParameterUninitializedException,
    RCLError,
    RCLInvalidROSArgsError,
    SetParametersResult,
    UnknownROSArgsError,
)
from cloth_bench_ros.runtime.qos import (  # noqa: F401 (re-exported as rclpy's names)
    as_profile,
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    time_source_qos,
)
from cloth_bench_ros.runtime.topic_endpoint_info import (
    TopicEndpointInfo,
    TopicEndpointTypeEnum,
)  # noqa: F401
from cloth_bench_ros.runtime.transport import IntraProcessTransport, transport_choice, TRANSPORTS

# --- parameters and arguments: runtime/parameters.py, runtime/arguments.py ---------------------


def make_transport(context: 'Context', name: str, domain_id: int | None = None) -> Any:
    """Return the transport `name` ('intra' or 'dds'); DDS loads Cyclone only when chosen."""
    if name == 'dds':
        from cloth_bench_ros.runtime.dds.transport import DdsTransport

        return DdsTransport(context, domain_id)
    if name not in TRANSPORTS:
        raise ValueError(f'unknown transport {name!r} (valid: intra, dds)')
    return IntraProcessTransport(context)


class Context:
    """One graph: its transport (intra-process or DDS), delivery queue and shutdown flag."""

    def __init__(self) -> None:
        self.args = RosArguments()
        self._ok = False
        self.subscriptions: dict[str, list['Subscription']] = {}
        self.publishers: dict[str, list['Publisher']] = {}
        self.queue: deque[tuple['Subscription', Any]] = deque()
        self.nodes: list['Node'] = []
        self.transport: Any = IntraProcessTransport(self)
        self.topic_types: dict[str, tuple[str, int]] = {}  # topic -> (type, endpoints using it)

    def init(
        self,
        args: list[str] | None = None,
        *,
        domain_id: int | None = None,
        transport: str | None = None,
    ) -> None:
        """Parse the ROS arguments and open the transport (default: CLOTH_BENCH_TRANSPORT)."""
        self.args = parse_ros_args(args)
        self.transport = make_transport(self, transport or transport_choice('intra'), domain_id)
        self._ok = True

    def ok(self) -> bool:
        return self._ok

    def claim_topic(self, topic: str, msg_type: Any, kind: str) -> None:
        """Count an endpoint on `topic`; a second type is refused, as rmw refuses it."""
        typename = msg_type.__msgtype__
        known, count = self.topic_types.get(topic, (typename, 0))
        if known != typename:
            raise RCLError(
                f'Failed to create {kind}: create_{kind}() called for existing topic name '
                f'{topic} with incompatible type {typename} (the topic has {known})'
            )
        self.topic_types[topic] = (typename, count + 1)

    def release_topic(self, topic: str) -> None:
        typename, count = self.topic_types.get(topic, ('', 1))
        if count > 1:
            self.topic_types[topic] = (typename, count - 1)
        else:
            self.topic_types.pop(topic, None)

    def enqueue(self, sub: 'Subscription', msg: Any) -> None:
        """Queue a message for `sub`; a keep-last reader keeps only its newest `depth` ones."""
        if sub.qos.history == HistoryPolicy.KEEP_LAST and sub._queued >= max(1, sub.qos.depth):
            sub._dropped += 1  # the oldest one still queued for it is skipped when reached
        else:
            sub._queued += 1
        self.queue.append((sub, msg))

    def shutdown(self) -> None:
        self._ok = False
        self.queue.clear()
        self.topic_types.clear()
        self.transport.shutdown()
        self.transport = IntraProcessTransport(self)


_default_context = Context()


def init(
    args: list[str] | None = None,
    context: Context | None = None,
    domain_id: int | None = None,
    transport: str | None = None,
) -> None:
    """rclpy.init; `transport` ('intra' or 'dds') is the embedded runtime's own addition."""
    (context or _default_context).init(args, domain_id=domain_id, transport=transport)


def create_node(node_name: str, *, context: Context | None = None, **kwargs: Any) -> 'Node':
    """rclpy.create_node."""
    return Node(node_name, context=context, **kwargs)


def ok(context: Context | None = None) -> bool:
    return (context or _default_context).ok()


def shutdown(context: Context | None = None) -> None:
    (context or _default_context).shutdown()


# --- node ------------------------------------------------------------------------------------


class Publisher:
    def __init__(self, node: 'Node', msg_type: Any, topic: str, qos: QoSProfile) -> None:
        self.node, self.msg_type, self.topic_name, self.qos = node, msg_type, topic, qos
        self._history: deque = deque(maxlen=max(1, qos.depth))

    def publish(self, msg: Any) -> None:
        """As rclpy: a message of the publisher's type, or its serialized bytes; else TypeError."""
        if isinstance(msg, bytes):
            msg = deserialize_message(msg, self.msg_type)
        elif not (
            isinstance(msg, self.msg_type)
            or getattr(type(msg), '__msgtype__', None) == self.msg_type.__msgtype__
        ):
            # rosbags' class of the same ROS type (what deserialize_message returns) is that type
            raise TypeError(f'Expected {self.msg_type}, got {type(msg)}')
        ctx = self.node.context
        if not ctx.ok():
            return
        ctx.transport.publish(self, msg)

    def get_subscription_count(self) -> int:
        """Subscriptions matched with this publisher (rmw: the writer's matched readers)."""
        return self.node.context.transport.matched_subscriptions(self)

    def destroy(self) -> None:
        self.node.context.transport.remove_publisher(self)
        self.node.context.release_topic(self.topic_name)


class Subscription:
    def __init__(
        self, node: 'Node', msg_type: Any, topic: str, callback: Callable, qos: QoSProfile
    ) -> None:
        self.node, self.msg_type, self.topic_name, self.callback, self.qos = (
            node,
            msg_type,
            topic,
            callback,
            qos,
        )
        self._queued = 0  # its messages in the context's queue
        self._dropped = 0  # of those, how many a keep-last depth has pushed out

    def get_publisher_count(self) -> int:
        """Return publishers matched with this subscription (rmw: the reader's matched writers)."""
        return self.node.context.transport.matched_publications(self)

    def destroy(self) -> None:
        self.node.context.transport.remove_subscription(self)
        self.node.context.release_topic(self.topic_name)


class Node:
    """The rclpy.node.Node subset listed in this module's docstring."""

    def __init__(
        self,
        node_name: str,
        *,
        namespace: str | None = None,
        parameter_overrides: list[Parameter] | None = None,
        context: Context | None = None,
        cli_args: list[str] | None = None,
        use_global_arguments: bool = True,
        **_: Any,
    ) -> None:
        self.context = context or _default_context
        if not self.context.ok():
            raise RuntimeError('rclpy.init() has not been called')
        local = parse_ros_args(cli_args) if cli_args else RosArguments()
        global_args = self.context.args if use_global_arguments else RosArguments()
        self._remaps = (
            local.remaps + global_args.remaps
        )  # rcl: local rules first, first match wins
        validate_node_name(node_name)
        self._name = remap_node_name(self._remaps, node_name)
        ns = remap_namespace(self._remaps, node_name, namespace or '/')
        self._namespace = ns if ns.startswith('/') else '/' + ns
        validate_node_name(self._name)
        validate_namespace(self._namespace)
        full = f'{self._namespace.rstrip("/")}/{self._name}'
        self._overrides: dict[str, Parameter] = {}
        for args in (global_args, local):  # rclpy node.cpp get_parameters: global, then the node's
            self._overrides.update(args.overrides.for_node(full))
        self._overrides.update({p.name: p for p in parameter_overrides or []})
        self._parameters: dict[str, Parameter] = {}
        self._descriptors: dict[str, ParameterDescriptor] = {}
        self._on_set_callbacks: list[Callable[[list[Parameter]], SetParametersResult]] = []
        self._timers: list[Timer] = []
        self._subscriptions: list[Subscription] = []
        self._publishers: list[Publisher] = []
        self._clock = Clock(clock_type=ClockType.ROS_TIME)
        self._logger = _Logger(logging.getLogger(f'cloth_bench_ros.{self._name}'), self._name)
        rcl_logger = full.lstrip('/').replace('/', '.')
        levels = {**global_args.log_levels, **local.log_levels}
        level = levels.get(rcl_logger, levels.get(''))
        if level is not None:  # --log-level [logger:=]severity, as rcl sets a node's logger
            self._logger._logger.setLevel(level)
        self.context.nodes.append(self)
        self.context.transport.graph_changed(self)
        # rclpy's TimeSource: use_sim_time declared as a bool; when true, /clock drives the clock.
        if self.declare_parameter('use_sim_time', False).value:
            self._clock.ros_time_is_active = True
            self.create_subscription(messages.Clock, '/clock', self._on_clock, time_source_qos())

    def _on_clock(self, msg: Any) -> None:
        self._clock.sim_time_ns = Time.from_msg(msg.clock).nanoseconds

    # names
    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        return f'{self._namespace.rstrip("/")}/{self._name}'

    def resolve_topic_name(self, topic: str, *, only_expand: bool = False) -> str:
        """Return the topic expanded and, unless only_expand, remapped (rcl_node_resolve_name)."""
        validate_topic_name(topic)
        full = expand_topic_name(topic, self._name, self._namespace)
        validate_full_topic_name(full)
        return (
            full
            if only_expand
            else remap_topic_name(self._remaps, full, self._name, self._namespace)
        )

    # parameters (rclpy/node.py declare_parameters, _apply_descriptor, get_parameter)
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
        for callback in self._on_set_callbacks:  # rclpy runs them on a declaration too
            result = callback([parameter])
            if not result.successful:
                raise InvalidParameterValueException(name, parameter.value, result.reason)
        self._parameters[name], self._descriptors[name] = parameter, descriptor
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
        """Set all or none: read-only and type checks, then the node's callbacks (rclpy)."""
        for parameter in parameter_list:
            if parameter.name not in self._parameters:
                raise ParameterNotDeclaredException(parameter.name)
            descriptor = self._descriptors[parameter.name]
            if descriptor.read_only:
                return SetParametersResult(
                    False, f'Trying to set a read-only parameter: {parameter.name}.'
                )
            if not descriptor.dynamic_typing and parameter.type_ != descriptor.type:
                return SetParametersResult(
                    False,
                    f"Wrong parameter type, expected 'Type.{ParameterType(descriptor.type).name}'"
                    f" got 'Type.{parameter.type_.name}'",
                )
        for callback in self._on_set_callbacks:
            result = callback(parameter_list)
            if not result.successful:
                return result
        for parameter in parameter_list:
            self._parameters[parameter.name] = parameter
            if self._descriptors[parameter.name].dynamic_typing:
                self._descriptors[parameter.name].type = int(parameter.type_)
        return SetParametersResult(True)

    def describe_parameter(self, name: str) -> ParameterDescriptor:
        if name not in self._descriptors:
            raise ParameterNotDeclaredException(name)
        return self._descriptors[name]

    # graph
    def create_publisher(
        self, msg_type: Any, topic: str, qos_profile: QoSProfile | int
    ) -> Publisher:
        pub = Publisher(self, msg_type, self.resolve_topic_name(topic), as_profile(qos_profile))
        self.context.claim_topic(pub.topic_name, msg_type, 'publisher')
        self._publishers.append(pub)
        self.context.transport.add_publisher(pub)
        return pub

    def create_subscription(
        self, msg_type: Any, topic: str, callback: Callable, qos_profile: QoSProfile | int
    ) -> Subscription:
        sub = Subscription(
            self, msg_type, self.resolve_topic_name(topic), callback, as_profile(qos_profile)
        )
        self.context.claim_topic(sub.topic_name, msg_type, 'subscription')
        self._subscriptions.append(sub)
        self.context.transport.add_subscription(sub)
        return sub

    def create_timer(
        self,
        timer_period_sec: float,
        callback: Callable,
        callback_group: Any = None,
        clock: Clock | None = None,
        **_: Any,
    ) -> Timer:
        """Return a timer on `clock`, by default the node's (sim time under use_sim_time)."""
        timer = Timer(timer_period_sec, callback, clock or self._clock)
        self._timers.append(timer)
        return timer

    def destroy_timer(self, timer: Timer) -> bool:
        timer.cancel()
        if timer in self._timers:
            self._timers.remove(timer)
        return True

    def count_subscribers(self, topic: str) -> int:
        return len(self.get_subscriptions_info_by_topic(topic))

    def count_publishers(self, topic: str) -> int:
        return len(self.get_publishers_info_by_topic(topic))

    def get_publishers_info_by_topic(
        self, topic_name: str, no_mangle: bool = False
    ) -> list[TopicEndpointInfo]:
        """Return every publisher of the topic in the graph, with its node (the name expanded)."""
        topic = topic_name if no_mangle else self.resolve_topic_name(topic_name, only_expand=True)
        return self.context.transport.endpoints(topic, TopicEndpointTypeEnum.PUBLISHER)

    def get_subscriptions_info_by_topic(
        self, topic_name: str, no_mangle: bool = False
    ) -> list[TopicEndpointInfo]:
        """Return every subscription of the topic in the graph, with its node."""
        topic = topic_name if no_mangle else self.resolve_topic_name(topic_name, only_expand=True)
        return self.context.transport.endpoints(topic, TopicEndpointTypeEnum.SUBSCRIPTION)

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        return self.context.transport.node_names()

    def get_clock(self) -> Clock:
        return self._clock

    def get_logger(self) -> '_Logger':
        return self._logger

    def destroy_node(self) -> None:
        for sub in self._subscriptions:
            sub.destroy()
        for pub in self._publishers:
            pub.destroy()
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        if self in self.context.nodes:
            self.context.nodes.remove(self)
            self.context.transport.graph_changed(self)


class _Logger:
    def __init__(self, logger: logging.Logger, name: str) -> None:
        self._logger, self._name = logger, name

    def _log(self, level: int, msg: str) -> None:
        self._logger.log(level, '[%s]: %s', self._name, msg)

    def debug(self, msg: str) -> None:
        self._log(logging.DEBUG, msg)

    def info(self, msg: str) -> None:
        self._log(logging.INFO, msg)

    def warning(self, msg: str) -> None:
        self._log(logging.WARNING, msg)

    warn = warning

    def error(self, msg: str) -> None:
        self._log(logging.ERROR, msg)

    def fatal(self, msg: str) -> None:
        self._log(logging.CRITICAL, msg)


# --- executors -------------------------------------------------------------------------------


class SingleThreadedExecutor:
    """Runs queued message callbacks in publish order, then due timers of its nodes."""

    def __init__(self, context: Context | None = None) -> None:
        self.context = context or _default_context
        self.nodes: list[Node] = []

    def add_node(self, node: Node) -> bool:
        if node not in self.nodes:
            self.nodes.append(node)
        return True

    def remove_node(self, node: Node) -> None:
        if node in self.nodes:
            self.nodes.remove(node)

    def _armed_timers(self) -> list[Timer]:
        return [t for n in self.nodes for t in n._timers if not t.cancelled]

    def _deliver_one(self) -> bool:
        self.context.transport.receive()
        queue = self.context.queue
        for _ in range(len(queue)):
            sub, msg = queue.popleft()
            if sub.node in self.nodes:
                if sub._dropped:  # pushed out by newer ones (keep-last depth)
                    sub._dropped -= 1
                    continue
                sub._queued -= 1
                sub.callback(msg)
                return True
            if sub.node in self.context.nodes:
                queue.append((sub, msg))  # for a node of another executor
        return False

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run one ready callback, waiting up to timeout_sec for a timer if none is ready."""
        if not self.context.ok() or self._deliver_one():
            return
        timers = self._armed_timers()
        ready = next((t for t in timers if t.is_ready()), None)
        if ready is None:
            # Timers on a sim clock become due only through /clock: no point sleeping for them.
            waits = [t.time_until_next_call() for t in timers if t.follows_wall_time]
            # The transport waits: a sleep in one process, a DDS wait set that a sample ends early.
            transport = self.context.transport
            if not waits:
                if timeout_sec:
                    transport.wait(
                        timeout_sec if transport.name == 'dds' else min(timeout_sec, 0.01)
                    )
                return
            wait = min(w for w in waits if w is not None) / 1e9
            if timeout_sec is not None and wait > timeout_sec:
                transport.wait(timeout_sec)
                return
            if transport.wait(max(wait, 0.0)):
                return  # a message came first: delivered on the next spin_once
            ready = next((t for t in timers if t.is_ready()), None)
        if ready is not None:
            ready.call()

    def spin(self) -> None:
        while self.context.ok():
            self.spin_once(0.1)

    def spin_until_idle(self) -> None:
        """Spin until no message is queued and no timer is armed (the run is complete)."""
        while self.context.ok() and (
            self.context.queue or any(t.follows_wall_time for t in self._armed_timers())
        ):
            self.spin_once(0.1)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self.nodes.clear()
        return True


def spin_once(
    node: Node, *, executor: SingleThreadedExecutor | None = None, timeout_sec: float | None = None
) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin_once(timeout_sec)


def spin(node: Node, executor: SingleThreadedExecutor | None = None) -> None:
    ex = executor or SingleThreadedExecutor(node.context)
    ex.add_node(node)
    ex.spin()


# --- serialization ---------------------------------------------------------------------------


def serialize_message(msg: Any) -> bytes:
    return cdr.serialize(msg)


def deserialize_message(data: bytes, msg_type: Any) -> Any:
    return cdr.deserialize(data, msg_type.__msgtype__)
