"""
The ROS graph over DDS, as rmw_cyclonedds and rmw_dds_common keep it.

DDS knows participants, writers and readers; ROS nodes exist only in `ros_discovery_info`: each
participant publishes a ParticipantEntitiesInfo (its GID and, per node, namespace, name and the
GIDs of the node's readers and writers) on that topic (reliable, transient local, keep last 1),
anew whenever a node or endpoint comes or goes. Joined with Cyclone's DCPSPublication and
DCPSSubscription built-in topics (endpoint GUID -> topic, type, QoS), that names the node of every
endpoint, which is what get_publishers_info_by_topic and `ros2 node list` report.
"""

from __future__ import annotations

from typing import Any
import uuid

from cloth_bench_ros.runtime.dds.cyclone_private import take_cdr
from cloth_bench_ros.runtime.dds.discovery_info import parse_participant_entities
from cloth_bench_ros.runtime.dds.idl import (
    Gid_,
    NodeEntitiesInfo_,
    ParticipantEntitiesInfo_,
    ros_type_name,
)
from cloth_bench_ros.runtime.dds.qos import endpoint_qos
from cloth_bench_ros.runtime.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from cloth_bench_ros.runtime.topic_endpoint_info import (
    TopicEndpointInfo,
    TopicEndpointTypeEnum,
    UNKNOWN_NODE,
)
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
    BuiltinTopicDcpsSubscription,
)
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

DISCOVERY_TOPIC = 'ros_discovery_info'
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any


def _discovery_profile(history: HistoryPolicy) -> QoSProfile:
    """Return the QoS of rmw_cyclonedds' discovery endpoints (rmw_node.cpp)."""
    return QoSProfile(
        depth=1,
        history=history,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


def _gid(guid: uuid.UUID) -> Gid_:
    return Gid_(data=list(guid.bytes))


def _key(gid: Gid_) -> bytes:
    return bytes(gid.data)


class Graph:
    """This participant's nodes announced on ros_discovery_info; everyone's endpoints read back."""

    def __init__(self, participant: DomainParticipant) -> None:
        self.participant = participant
        self.gid = _gid(participant.get_guid())
        topic = Topic(participant, DISCOVERY_TOPIC, ParticipantEntitiesInfo_)
        self.writer = DataWriter(
            participant, topic, qos=endpoint_qos(_discovery_profile(HistoryPolicy.KEEP_LAST))
        )
        self.reader = DataReader(
            participant,
            topic,
            qos=endpoint_qos(_discovery_profile(HistoryPolicy.KEEP_ALL), ignore_local=True),
        )
        self.builtin = {
            TopicEndpointTypeEnum.PUBLISHER: BuiltinDataReader(
                participant, BuiltinTopicDcpsPublication
            ),
            TopicEndpointTypeEnum.SUBSCRIPTION: BuiltinDataReader(
                participant, BuiltinTopicDcpsSubscription
            ),
        }
        self.participants = BuiltinDataReader(participant, BuiltinTopicDcpsParticipant)
        self.local: dict[Any, NodeEntitiesInfo_] = {}  # embedded Node -> its entry
        self.remote: dict[bytes, list[NodeEntitiesInfo_]] = {}  # participant GID -> its nodes
        self.endpoint_cache: dict[TopicEndpointTypeEnum, dict[uuid.UUID, Any]] = {
            k: {} for k in self.builtin
        }

    # this participant's nodes
    def update_node(self, node: Any, readers: list[uuid.UUID], writers: list[uuid.UUID]) -> None:
        """Record a node's endpoints (GUIDs) and publish the participant's entities info."""
        self.local[node] = NodeEntitiesInfo_(
            node_namespace=node.get_namespace(),
            node_name=node.get_name(),
            reader_gid_seq=[_gid(g) for g in readers],
            writer_gid_seq=[_gid(g) for g in writers],
        )
        self.announce()

    def remove_node(self, node: Any) -> None:
        if self.local.pop(node, None) is not None:
            self.announce()

    def announce(self) -> None:
        self.writer.write(
            ParticipantEntitiesInfo_(
                gid=self.gid, node_entities_info_seq=list(self.local.values())
            )
        )

    # everyone's
    def _refresh(self) -> None:
        samples = take_cdr(self.reader, _ANY, 1000)  # raw: Humble's GIDs are 24 bytes
        for payload, info in samples if not isinstance(samples, int) else ():
            if not info.valid_data:
                continue
            try:
                sample = parse_participant_entities(payload)
            except ValueError:  # not a ROS participant's graph message: nothing to learn
                continue
            self.remote[_key(sample.gid)] = list(sample.node_entities_info_seq)  # latest wins
        for sample in self.participants.take(
            N=1000
        ):  # a participant that left takes its nodes along
            if sample.sample_info.instance_state != InstanceState.Alive:
                self.remote.pop(sample.key.bytes, None)
        for kind, reader in self.builtin.items():
            cache = self.endpoint_cache[kind]
            for sample in reader.take(N=1000):
                if (
                    sample.sample_info.valid_data
                    and sample.sample_info.instance_state == InstanceState.Alive
                ):
                    cache[sample.key] = sample
                else:
                    cache.pop(sample.key, None)

    def _owner(self, guid: uuid.UUID, kind: TopicEndpointTypeEnum) -> tuple[str, str]:
        entries = list(self.local.values()) + [n for nodes in self.remote.values() for n in nodes]
        for entry in entries:
            gids = (
                entry.writer_gid_seq
                if kind == TopicEndpointTypeEnum.PUBLISHER
                else entry.reader_gid_seq
            )
            if any(bytes(g.data) == guid.bytes for g in gids):
                return entry.node_name, entry.node_namespace
        return UNKNOWN_NODE

    def endpoints(self, dds_topic: str, kind: TopicEndpointTypeEnum) -> list[TopicEndpointInfo]:
        """Every writer or reader of a DDS topic in the domain, with its node's name."""
        self._refresh()
        out = []
        for endpoint in self.endpoint_cache[kind].values():
            if endpoint.topic_name != dds_topic:
                continue
            name, namespace = self._owner(endpoint.key, kind)
            out.append(
                TopicEndpointInfo(
                    name,
                    namespace,
                    ros_type_name(endpoint.type_name),
                    kind,
                    list(endpoint.key.bytes),
                    _profile(endpoint.qos),
                )
            )
        return out

    def node_names(self) -> list[tuple[str, str]]:
        """(name, namespace) of every node in the domain, this participant's first."""
        self._refresh()
        entries = list(self.local.values()) + [n for nodes in self.remote.values() for n in nodes]
        return [(e.node_name, e.node_namespace) for e in entries]


def _profile(qos: Any) -> QoSProfile:
    """Return a QoSProfile of the embedded runtime from a discovered endpoint's Cyclone QoS."""

    def policy(kind: Any) -> Any:
        return qos[kind] if qos is not None and kind in qos else None

    history, reliability, durability = (
        policy(Policy.History),
        policy(Policy.Reliability),
        policy(Policy.Durability),
    )
    return QoSProfile(
        depth=getattr(history, 'depth', 0),
        history=(
            HistoryPolicy.KEEP_ALL
            if history is Policy.History.KeepAll
            else HistoryPolicy.KEEP_LAST
        ),
        reliability=(
            ReliabilityPolicy.BEST_EFFORT
            if reliability is Policy.Reliability.BestEffort
            else ReliabilityPolicy.RELIABLE
        ),
        durability=(
            DurabilityPolicy.TRANSIENT_LOCAL
            if durability is Policy.Durability.TransientLocal
            else DurabilityPolicy.VOLATILE
        ),
    )
