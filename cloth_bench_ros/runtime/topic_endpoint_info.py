"""rclpy.topic_endpoint_info for the embedded runtime (a leaf module)."""

from __future__ import annotations

from dataclasses import dataclass, field
import enum

from cloth_bench_ros.runtime.qos import QoSProfile

# What rmw_dds_common's graph cache (and so rclpy) names an endpoint whose node is not known yet.
UNKNOWN_NODE = ('_NODE_NAME_UNKNOWN_', '_NODE_NAMESPACE_UNKNOWN_')


class TopicEndpointTypeEnum(enum.IntEnum):
    """rclpy.topic_endpoint_info.TopicEndpointTypeEnum."""

    INVALID = 0
    PUBLISHER = 1
    SUBSCRIPTION = 2


@dataclass(frozen=True)
class TopicEndpointInfo:
    """rclpy.topic_endpoint_info.TopicEndpointInfo: who publishes or subscribes, and how."""

    node_name: str
    node_namespace: str
    topic_type: str
    endpoint_type: TopicEndpointTypeEnum
    endpoint_gid: list[int] = field(default_factory=list)
    qos_profile: QoSProfile | None = None
