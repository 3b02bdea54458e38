"""
ROS 2 QoS profiles as rmw_cyclonedds maps them onto Cyclone DDS endpoints.

`endpoint_qos` follows rmw_cyclonedds' create_readwrite_qos: history keep-last depth (or keep
all), reliability, durability (transient local keeps `depth` samples through the durability
service), automatic liveliness, no autodispose, the type hash in USER_DATA. The domain and its
discovery settings are runtime/dds/domain.py.
"""

from __future__ import annotations

from cloth_bench_ros.data.messages import type_hash
from cloth_bench_ros.runtime.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from cyclonedds.qos import Policy, Qos

_INFINITY = 0x7FFFFFFFFFFFFFFF  # DDS_INFINITY, ns


def endpoint_qos(
    profile: QoSProfile,
    ros_type: str | None = None,
    *,
    ignore_local: bool = False,
    user_data: str = '',
) -> Qos:
    """
    Return the Cyclone QoS of a writer or reader created from a rclpy-style QoSProfile.

    USER_DATA is `user_data` (a service's `serviceid=...;`) and the type's `typehash=...;`.
    """
    depth = int(profile.depth)
    if int(profile.history) == HistoryPolicy.KEEP_ALL:
        history = Policy.History.KeepAll
    else:  # KEEP_LAST, SYSTEM_DEFAULT (depth 0 is rmw's "system default": 1)
        history = Policy.History.KeepLast(depth if depth > 0 else 1)
    reliability = (
        Policy.Reliability.BestEffort
        if int(profile.reliability) == ReliabilityPolicy.BEST_EFFORT
        else Policy.Reliability.Reliable(max_blocking_time=_INFINITY)
    )
    policies = [
        Policy.WriterDataLifecycle(autodispose=False),
        history,
        reliability,
        Policy.Liveliness.Automatic(lease_duration=_INFINITY),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if int(profile.durability) == DurabilityPolicy.TRANSIENT_LOCAL:
        policies += [
            Policy.Durability.TransientLocal,
            Policy.DurabilityService(
                cleanup_delay=0,
                history=history,
                max_samples=-1,
                max_instances=-1,
                max_samples_per_instance=-1,
            ),
        ]
    else:
        policies.append(Policy.Durability.Volatile)
    if ignore_local:
        policies.append(Policy.IgnoreLocal.Participant)
    if ros_type is not None:
        user_data += f'typehash={type_hash(ros_type)};'
    if user_data:
        policies.append(Policy.Userdata(data=user_data.encode()))
    return Qos(*policies)
