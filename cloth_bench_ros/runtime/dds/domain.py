"""
The DDS domain and its discovery, as rmw_cyclonedds configures Cyclone DDS from the environment.

`domain_id` reads ROS_DOMAIN_ID as rcl does. `domain_config` follows rmw_cyclonedds'
check_create_domain: ROS_AUTOMATIC_DISCOVERY_RANGE (or ROS_LOCALHOST_ONLY=1) and ROS_STATIC_PEERS
become a configuration fragment placed before CYCLONEDDS_URI; LOCALHOST here also pins Cyclone to
the loopback interface (unless CYCLONEDDS_URI names interfaces), so nothing leaves the machine.
`loopback_environment` is the environment of tests and benchmarks (loopback only).
"""

from __future__ import annotations

import os
from typing import Mapping

from cloth_bench_ros.errors import InputError


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
