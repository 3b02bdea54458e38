"""rclpy.node for the embedded runtime: Node, Publisher, Subscription (parameters: mixed in)."""

from __future__ import annotations

from collections import deque
import logging
from typing import Any, Callable

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
from cloth_bench_ros.runtime.clock import Clock, ClockType, Timer
from cloth_bench_ros.runtime.context import Context, default_context
from cloth_bench_ros.runtime.node_parameters import NodeParameters
from cloth_bench_ros.runtime.parameter_service import ParameterService
from cloth_bench_ros.runtime.parameters import Parameter, ParameterDescriptor, SetParametersResult
from cloth_bench_ros.runtime.qos import as_profile, QoSProfile, time_source_qos
from cloth_bench_ros.runtime.rosout import (
    Log,
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
from cloth_bench_ros.runtime.services import Client, Service, services_qos
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
        self.handle = callback  # what the executor calls (services and clients have theirs)
        self._queued = 0  # its messages in the context's queue
        self._dropped = 0  # of those, how many a keep-last depth has pushed out

    def get_publisher_count(self) -> int:
        """Return publishers matched with this subscription (rmw: the reader's matched writers)."""
        return self.node.context.transport.matched_publications(self)

    def destroy(self) -> None:
        self.node.context.transport.remove_subscription(self)
        self.node.context.release_topic(self.topic_name)


class Node(NodeParameters):
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
        start_parameter_services: bool = True,
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
        self._services: list[Service] = []
        self._clients: list[Client] = []
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
        if start_parameter_services:  # rclpy's ParameterService
            ParameterService(self)
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
        stamp = msg.clock  # Time.from_msg's sum, without building a Time per /clock message
        self._clock.sim_time_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)

    # names
    def get_name(self) -> str:
        return self._name

    def get_namespace(self) -> str:
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        return f'{self._namespace.rstrip("/")}/{self._name}'

    def resolve_topic_name(self, topic: str, *, only_expand: bool = False) -> str:
        """Return the topic expanded and, unless only_expand, remapped (rcl_node_resolve_name)."""
        return self._resolve(topic, only_expand, 'topic')

    def resolve_service_name(self, service: str, *, only_expand: bool = False) -> str:
        """Return the service name expanded and, unless only_expand, remapped (rosservice://)."""
        return self._resolve(service, only_expand, 'service')

    def _resolve(self, name: str, only_expand: bool, kind: str) -> str:
        validate_topic_name(name)
        full = expand_topic_name(name, self._name, self._namespace)
        validate_full_topic_name(full)
        return (
            full
            if only_expand
            else remap_topic_name(self._remaps, full, self._name, self._namespace, kind)
        )

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

    def create_service(
        self,
        srv_type: Any,
        srv_name: str,
        callback: Callable[[Any, Any], Any],
        *,
        qos_profile: QoSProfile | None = None,
        **_: Any,
    ) -> Service:
        """Return a service: `callback(request, response)` fills and returns the response."""
        name = self.resolve_service_name(srv_name)
        srv = Service(self, srv_type, srv_name, name, callback, qos_profile or services_qos())
        self._services.append(srv)
        self.context.transport.add_service(srv)
        return srv

    def create_client(
        self, srv_type: Any, srv_name: str, *, qos_profile: QoSProfile | None = None, **_: Any
    ) -> Client:
        name = self.resolve_service_name(srv_name)
        client = Client(self, srv_type, srv_name, name, qos_profile or services_qos())
        self._clients.append(client)
        self.context.transport.add_client(client)
        return client

    def destroy_service(self, service: Service) -> bool:
        if service in self._services:
            self._services.remove(service)
            service.destroy()
        return True

    def destroy_client(self, client: Client) -> bool:
        if client in self._clients:
            self._clients.remove(client)
            client.destroy()
        return True

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
        for srv in self._services:
            srv.destroy()
        for client in self._clients:
            client.destroy()
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
