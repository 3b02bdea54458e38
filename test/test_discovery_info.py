"""
ros_discovery_info of Humble (24-byte GIDs) and of Iron on (16-byte GIDs) name the same nodes.

The samples are written by rosbags' serialiser with its Humble and Jazzy type stores (not by the
project), and over real Cyclone DDS by a plain participant that announces a node the way a Humble
rmw_cyclonedds does.
"""

from __future__ import annotations

import time

from cloth_bench_ros.runtime import embedded as rclpy
from cloth_bench_ros.runtime.dds.discovery_info import parse_participant_entities
from cloth_bench_ros.runtime.dds.domain import domain_id
from cloth_bench_ros.runtime.dds.graph import DISCOVERY_TOPIC
from cloth_bench_ros.runtime.dds.idl import dds_type, ParticipantEntitiesInfo_
from cloth_bench_ros.runtime.dds.transport import padded
from cyclonedds._clayer import ddspy_write
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.topic import Topic
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

PARTICIPANT = bytes(range(1, 17))
READER, WRITER = bytes(range(20, 36)), bytes(range(40, 56))


def _sample(store: Stores, participant: bytes, nodes: list[tuple[str, str, list, list]]) -> bytes:
    """Return a ParticipantEntitiesInfo as `store`'s ROS 2 serialises it (GIDs zero-padded)."""
    types = get_typestore(store)
    size = types.fielddefs['rmw_dds_common/msg/Gid'][1][0][1][1][1]  # char data[size]
    gid_class = types.types['rmw_dds_common/msg/Gid']
    node_class = types.types['rmw_dds_common/msg/NodeEntitiesInfo']
    info_class = types.types['rmw_dds_common/msg/ParticipantEntitiesInfo']

    def gid(raw: bytes):
        return gid_class(data=np.frombuffer(raw.ljust(size, b'\0'), dtype=np.uint8))

    info = info_class(
        gid=gid(participant),
        node_entities_info_seq=[
            node_class(ns, name, [gid(g) for g in readers], [gid(g) for g in writers])
            for ns, name, readers, writers in nodes
        ],
    )
    return bytes(types.serialize_cdr(info, 'rmw_dds_common/msg/ParticipantEntitiesInfo'))


@pytest.mark.parametrize('store', [Stores.ROS2_HUMBLE, Stores.ROS2_JAZZY])
def test_humble_and_jazzy_samples_name_the_same_nodes(store):
    nodes = [('/cloth_bench', 'simulator', [READER], [WRITER]), ('/', 'lonely', [], [])]
    payload = _sample(store, PARTICIPANT, nodes)
    assert len(payload) > 24 + 2 * 24 if store == Stores.ROS2_HUMBLE else True
    info = parse_participant_entities(payload)
    assert bytes(info.gid.data) == PARTICIPANT
    named = [
        (n.node_namespace, n.node_name, [bytes(g.data) for g in n.reader_gid_seq],
         [bytes(g.data) for g in n.writer_gid_seq])
        for n in info.node_entities_info_seq
    ]
    assert named == nodes


@pytest.mark.parametrize('store', [Stores.ROS2_HUMBLE, Stores.ROS2_JAZZY])
def test_a_participant_without_nodes_reads_as_such(store):
    info = parse_participant_entities(_sample(store, PARTICIPANT, []))
    assert bytes(info.gid.data) == PARTICIPANT and info.node_entities_info_seq == []


def test_a_sample_of_another_shape_is_refused():
    with pytest.raises(ValueError, match='not readable'):
        parse_participant_entities(b'\x00\x01\x00\x00' + b'\xff' * 40)


def test_an_embedded_node_sees_the_name_of_a_humble_node_over_dds():
    """A plain participant announces `humble_talker` with 24-byte GIDs; its writer is named."""
    context = rclpy.Context()
    rclpy.init(args=[], context=context, transport='dds')
    try:
        observer = rclpy.create_node('observer', context=context)
        humble = DomainParticipant(domain_id())
        chatter = DataWriter(humble, Topic(humble, 'rt/chatter', dds_type('std_msgs/msg/String')))
        reliable = Qos(
            Policy.Reliability.Reliable(0), Policy.Durability.TransientLocal,
            Policy.History.KeepLast(1),
        )
        announce = DataWriter(
            humble, Topic(humble, DISCOVERY_TOPIC, ParticipantEntitiesInfo_), qos=reliable
        )
        sample = _sample(
            Stores.ROS2_HUMBLE,
            humble.get_guid().bytes,
            [('/', 'humble_talker', [], [chatter.get_guid().bytes])],
        )
        assert ddspy_write(announce._ref, padded(sample)) >= 0
        deadline = time.monotonic() + 10
        names: list = []
        while time.monotonic() < deadline:
            names = [
                (i.node_name, i.node_namespace)
                for i in observer.get_publishers_info_by_topic('/chatter')
            ]
            if names and names[0][0] != '_NODE_NAME_UNKNOWN_':
                break
            time.sleep(0.1)
        assert names == [('humble_talker', '/')]
    finally:
        rclpy.shutdown(context=context)
