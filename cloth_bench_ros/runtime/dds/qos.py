"""
ROS 2 QoS profiles and discovery settings as rmw_cyclonedds maps them onto Cyclone DDS.

`endpoint_qos` follows rmw_cyclonedds' create_readwrite_qos: history keep-last depth (or keep
all), reliability, durability (transient local keeps `depth` samples through the durability
service), automatic liveliness, no autodispose, the type hash in USER_DATA. `domain_config`
follows its check_create_domain: ROS_AUTOMATIC_DISCOVERY_RANGE (or ROS_LOCALHOST_ONLY=1) and
ROS_STATIC_PEERS become a configuration fragment placed before CYCLONEDDS_URI; LOCALHOST here also
pins Cyclone to the loopback interface (unless CYCLONEDDS_URI names interfaces), so nothing leaves
the machine.
"""

from __future__ import annotations

import os
from typing import Mapping

from cloth_bench_ros.data.messages import type_hash
from cloth_bench_ros.errors import InputError
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


def domain_id(environ: Mapping[str, str] = os.environ) -> int:
    """ROS_DOMAIN_ID (default 0), checked as rcl checks it: an integer from 0 to 232."""
    text = environ.get('ROS_DOMAIN_ID', '').strip()
    if not text:
        return 0
    if not text.isdigit() or int(text) > 232:
        raise InputError(f'ROS_DOMAIN_ID: expected an integer from 0 to 232, got {text!r}')
    return int(text)


def discovery_range(environ: Mapping[str, str] = os.environ) -> str:
    """SUBNET (default), LOCALHOST, OFF or SYSTEM_DEFAULT; ROS_LOCALHOST_ONLY=1 means LOCALHOST."""
    if environ.get('ROS_LOCALHOST_ONLY', '').strip() == '1':
        return 'LOCALHOST'
    text = environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '').strip().upper()
    if text and text not in ('SUBNET', 'LOCALHOST', 'OFF', 'SYSTEM_DEFAULT'):
        raise InputError(f'ROS_AUTOMATIC_DISCOVERY_RANGE: unknown value {text!r}')
    return text or 'SUBNET'


def domain_config(environ: Mapping[str, str] = os.environ) -> str:
    """Return the domain's Cyclone configuration: the discovery fragment, then CYCLONEDDS_URI."""
    scope = discovery_range(environ)
    peers = [p.strip() for p in environ.get('ROS_STATIC_PEERS', '').split(';') if p.strip()]
    config = ''
    if scope in ('LOCALHOST', 'OFF') or (scope == 'SUBNET' and peers):
        general = ''
        if scope in ('LOCALHOST', 'OFF'):
            general = '<General><AllowMulticast>false</AllowMulticast>'
            if scope == 'LOCALHOST' and 'NetworkInterface' not in environ.get(
                'CYCLONEDDS_URI', ''
            ):
                # Cyclone refuses an interface named twice: CYCLONEDDS_URI's own choice stands.
                general += '<Interfaces><NetworkInterface name="lo"/></Interfaces>'
            general += '</General>'
        if scope == 'OFF':
            discovery = (
                '<Discovery><ParticipantIndex>none</ParticipantIndex>'
                f'<Tag>ros_discovery_off_{os.getpid()}</Tag>'
            )
        else:
            discovery = (
                '<Discovery><ParticipantIndex>auto</ParticipantIndex>'
                '<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>'
            )
            listed = (['localhost'] if scope == 'LOCALHOST' else []) + peers
            if listed:
                discovery += (
                    '<Peers>' + ''.join(f'<Peer address="{p}"/>' for p in listed) + '</Peers>'
                )
        config = f'<CycloneDDS><Domain>{general}{discovery}</Discovery></Domain></CycloneDDS>,'
    return config + environ.get('CYCLONEDDS_URI', '')


LOOPBACK_URI = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface'
    ' name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>'
    '<ParticipantIndex>auto</ParticipantIndex>'
    '<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers><Peer'
    ' address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>'
)
"""CYCLONEDDS_URI that keeps Cyclone on loopback: interface lo, no multicast, peer 127.0.0.1."""


def loopback_environment(domain: int) -> dict[str, str]:
    """Return the environment of a DDS graph confined to loopback on `domain`."""
    return {
        'CYCLONEDDS_URI': LOOPBACK_URI,
        'ROS_LOCALHOST_ONLY': '1',
        'ROS_DOMAIN_ID': str(domain),
    }
