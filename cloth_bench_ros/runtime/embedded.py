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
  spin_once(node, timeout_sec), spin_until_future_complete(node, future, timeout_sec=)
- services: Node.create_service / create_client, Client.call_async (a Future),
  wait_for_service, service_is_ready; every node's parameter services
  (runtime/parameter_service.py)
  with rcl_interfaces/srv's six types, carried over DDS as rmw_cyclonedds carries them
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
- what every node publishes: /rosout and /parameter_events (runtime/rosout.py)

This module is the facade, as rclpy's __init__ is: the context is in runtime/context.py, Node,
Publisher and Subscription in runtime/node.py, the executor in runtime/executors.py.

QoS as DDS applies it, on either transport: incompatible writers and readers do not match, a
keep-last reader keeps its newest `depth` messages, a keep-all reader loses nothing.
"""

from __future__ import annotations

from typing import Any

from cloth_bench_ros.runtime.clock import (  # noqa: F401 (rclpy's names)
    Clock,
    ClockType,
    Time,
    Timer,
)
from cloth_bench_ros.runtime.context import Context, default_context, make_transport  # noqa: F401
from cloth_bench_ros.runtime.executors import (  # noqa: F401 (rclpy's names)
    SingleThreadedExecutor,
    spin,
    spin_once,
    spin_until_future_complete,
)
from cloth_bench_ros.runtime.node import Node, Publisher, Subscription  # noqa: F401
from cloth_bench_ros.runtime.parameter_errors import (  # noqa: F401 (rclpy's names)
    InvalidParameterException,
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterAlreadyDeclaredException,
    ParameterException,
    ParameterNotDeclaredException,
    ParameterUninitializedException,
    RCLError,
    RCLInvalidROSArgsError,
    UnknownROSArgsError,
)
from cloth_bench_ros.runtime.parameters import (  # noqa: F401 (re-exported as rclpy's names)
    Parameter,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from cloth_bench_ros.runtime.params_file import load_params_file  # noqa: F401
from cloth_bench_ros.runtime.qos import (  # noqa: F401 (re-exported as rclpy's names)
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from cloth_bench_ros.runtime.rosout import Log, ParameterEvent  # noqa: F401
from cloth_bench_ros.runtime.serialization import (  # noqa: F401 (rclpy's names)
    deserialize_message,
    serialize_message,
)
from cloth_bench_ros.runtime.services import (  # noqa: F401 (rclpy's names)
    Client,
    DescribeParameters,
    Future,
    GetParameters,
    GetParameterTypes,
    ListParameters,
    Service,
    SetParameters,
    SetParametersAtomically,
)
from cloth_bench_ros.runtime.topic_endpoint_info import (  # noqa: F401
    TopicEndpointInfo,
    TopicEndpointTypeEnum,
)


def init(
    args: list[str] | None = None,
    context: Context | None = None,
    domain_id: int | None = None,
    transport: str | None = None,
) -> None:
    """rclpy.init; `transport` ('intra' or 'dds') is the embedded runtime's own addition."""
    (context or default_context).init(args, domain_id=domain_id, transport=transport)


def create_node(node_name: str, *, context: Context | None = None, **kwargs: Any) -> Node:
    """rclpy.create_node."""
    return Node(node_name, context=context, **kwargs)


def ok(context: Context | None = None) -> bool:
    return (context or default_context).ok()


def shutdown(context: Context | None = None) -> None:
    (context or default_context).shutdown()
