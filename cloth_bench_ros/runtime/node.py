"""rclpy.node for the embedded runtime: Node, Publisher and Subscription (the nodes' subset)."""

from __future__ import annotations

from collections import deque
import dataclasses
import logging
from typing import Any, Callable, Sequence
import warnings

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
from cloth_bench_ros.runtime.clock import Clock, ClockType, Time, Timer
from cloth_bench_ros.runtime.context import Context, default_context
from cloth_bench_ros.runtime.parameters import (
    InvalidParameterException,
    InvalidParameterTypeException,
    InvalidParameterValueException,
    Parameter,
    ParameterAlreadyDeclaredException,
    ParameterDescriptor,
    ParameterNotDeclaredException,
    ParameterType,
    ParameterUninitializedException,
    SetParametersResult,
)
from cloth_bench_ros.runtime.qos import as_profile, QoSProfile, time_source_qos
from cloth_bench_ros.runtime.rosout import (
    Log,
    parameter_event,
    parameter_events_qos,
    PARAMETER_EVENTS_TOPIC,
    ParameterEvent,
    PROCESS_LOG_LEVELS,
    rcl_logger_name,
    RcutilsLogger,
    rosout_qos,
    ROSOUT_TOPIC,
)
from cloth_bench_ros.runtime.serialization import deserialize_message
from cloth_bench_ros.runtime.topic_endpoint_info import TopicEndpointInfo, TopicEndpointTypeEnum


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
        self.context = context or default_context
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
        self.context.nodes.append(self)
        # What every node publishes (runtime/rosout.py): parameter events (rclpy), /rosout (rcl).
        self._parameter_events = self.create_publisher(
            ParameterEvent, PARAMETER_EVENTS_TOPIC, parameter_events_qos()
        )
        rosout = (
            self.create_publisher(Log, ROSOUT_TOPIC, rosout_qos()).publish
            if global_args.rosout
            else None
        )
        rcl_logger = rcl_logger_name(self._namespace, self._name)
        self._logger = RcutilsLogger(
            logging.getLogger(f'cloth_bench_ros.{self._name}'), rcl_logger, self._name, rosout
        )
        levels = {**PROCESS_LOG_LEVELS, **local.log_levels}
        level = levels.get(rcl_logger) or levels.get('')  # unset: the default's (rcutils)
        if level:  # --log-level [logger:=]severity, as rcl sets a node's logger
            self._logger.set_level(level)
        self.context.transport.graph_changed(self)
        # rclpy's TimeSource: use_sim_time declared as a bool; when true, /clock drives the clock.
        if self.declare_parameter('use_sim_time', False).value:
            self._clock.ros_time_is_active = True
            self.create_subscription(messages.Clock, '/clock', self._on_clock, time_source_qos())
        # Declared by every Jazzy node (rclpy's type description service; there is none here).
        self.declare_parameter(
            'start_type_description_service',
            True,
            ParameterDescriptor(
                description='If enabled, start the ~/get_type_description service.',
                read_only=True,
            ),
        )

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

    def get_logger(self) -> RcutilsLogger:
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
