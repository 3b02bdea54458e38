"""
The embedded runtime's DDS transport: Cyclone DDS speaking ROS 2's wire protocol.

One DomainParticipant per context (as rmw_cyclonedds since Galactic), one writer per publisher and
one reader per subscription, on the DDS topic `rt` + the fully qualified ROS topic name, with the
rosidl type of idl.py and the QoS of qos.py. Payloads are rosbags' CDR (data/messages.py, the
project's one serialisation) written and taken as serialized samples: Cyclone's own Python
serializer packs a uint8[] element by element (about 15 ms for a 20k-point cloud), the bytes go
through unchanged here. The XTypes type information still comes from the declared IDL types, so
readers declared from ROS 2's IDL match.
"""

from __future__ import annotations

from typing import Any
import uuid

from cloth_bench_ros.data import messages as cdr
from cloth_bench_ros.runtime.dds.cyclone_private import delete_entity, take_cdr, write_cdr
from cloth_bench_ros.runtime.dds.domain import domain_config, domain_id
from cloth_bench_ros.runtime.dds.graph import Graph
from cloth_bench_ros.runtime.dds.idl import dds_type
from cloth_bench_ros.runtime.dds.qos import endpoint_qos
from cloth_bench_ros.runtime.dds.services import DdsServices
from cloth_bench_ros.runtime.topic_endpoint_info import TopicEndpointInfo, TopicEndpointTypeEnum
from cloth_bench_ros.runtime.transport import Endpoint
from cyclonedds.core import (
    DDSException,
    GuardCondition,
    InstanceState,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

ROS_TOPIC_PREFIX = 'rt'  # rmw_cyclonedds namespace_prefix.hpp
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any
_TAKE_BATCH = 64
_INFINITE_NS = 0x7FFFFFFFFFFFFFFF
_domains: dict[int, Domain] = {}  # one configured Cyclone domain per id and process, kept alive


def dds_topic_name(ros_topic: str) -> str:
    """`/cloth_bench/targets` -> `rt/cloth_bench/targets` (rmw_cyclonedds make_fqtopic)."""
    return ROS_TOPIC_PREFIX + ros_topic


def padded(payload: bytes) -> bytes:
    """Return a serialized sample zero-padded to a multiple of 4 bytes, as Cyclone sends it."""
    return payload + b'\0' * (-len(payload) % 4)


def _participant(domain: int) -> DomainParticipant:
    """Return a participant on `domain`, its Cyclone domain configured from the ROS environment."""
    if domain not in _domains:
        config = domain_config()
        if config:
            _domains[domain] = Domain(domain, config)
    # rmw_cyclonedds' participant USER_DATA names the enclave; ROS tools read it.
    return DomainParticipant(domain, qos=Qos(Policy.Userdata(data=b'enclave=/;')))


class DdsTransport:
    """Writers and readers of one context's publishers and subscriptions on a DDS domain."""

    name = 'dds'

    def __init__(self, context: Any, domain: int | None = None) -> None:
        self.context = context
        self.domain_id = domain_id() if domain is None else domain
        self.participant = _participant(self.domain_id)
        self.waitset = WaitSet(self.participant)
        self.wakeup = GuardCondition(self.participant)
        self.waitset.attach(self.wakeup)
        self.topics: dict[str, Topic] = {}
        self.writers: dict[Endpoint, DataWriter] = {}
        self.readers: dict[Endpoint, tuple[DataReader, ReadCondition]] = {}
        self.graph = Graph(self.participant)
        self.services = DdsServices(self)

    def topic(self, name: str, ros_type: str) -> Topic:
        """Return the DDS topic `name` (e.g. `rt/clock`) of a ROS type, created on first use."""
        if name not in self.topics:
            self.topics[name] = Topic(self.participant, name, dds_type(ros_type))
        return self.topics[name]

    @staticmethod
    def dispose(entity: Any) -> None:
        delete_entity(entity)

    # endpoints
    def add_publisher(self, pub: Endpoint) -> None:
        ros_type = pub.msg_type.__msgtype__
        self.writers[pub] = DataWriter(
            self.participant,
            self.topic(dds_topic_name(pub.topic_name), ros_type),
            qos=endpoint_qos(pub.qos, ros_type),
        )
        self.graph_changed(pub.node)

    def remove_publisher(self, pub: Endpoint) -> None:
        writer = self.writers.pop(pub, None)
        if writer is not None:
            delete_entity(writer)
            self.graph_changed(pub.node)

    def add_subscription(self, sub: Endpoint) -> None:
        ros_type = sub.msg_type.__msgtype__
        reader = DataReader(
            self.participant,
            self.topic(dds_topic_name(sub.topic_name), ros_type),
            qos=endpoint_qos(sub.qos, ros_type),
        )
        condition = ReadCondition(reader, _ANY)
        self.waitset.attach(condition)
        self.readers[sub] = (reader, condition)
        self.graph_changed(sub.node)

    def remove_subscription(self, sub: Endpoint) -> None:
        entry = self.readers.pop(sub, None)
        if entry is not None:
            reader, condition = entry
            self.waitset.detach(condition)
            delete_entity(condition)
            delete_entity(reader)
            self.graph_changed(sub.node)

    def graph_changed(self, node: Any) -> None:
        """Announce the node's current readers and writers on ros_discovery_info."""
        if node not in self.context.nodes:
            self.graph.remove_node(node)
            return
        readers = [r.get_guid() for s, (r, _) in self.readers.items() if s.node is node]
        writers = [w.get_guid() for p, w in self.writers.items() if p.node is node]
        service_readers, service_writers = self.services.guids(node)
        self.graph.update_node(node, readers + service_readers, writers + service_writers)

    # services (runtime/dds/services.py)
    def add_service(self, srv: Any) -> None:
        self.services.add(srv, is_service=True)

    def add_client(self, client: Any) -> None:
        self.services.add(client, is_service=False)

    def remove_service(self, srv: Any) -> None:
        self.services.remove(srv)

    def remove_client(self, client: Any) -> None:
        self.services.remove(client)

    def send_request(self, client: Any, sequence: int, request: Any) -> None:
        self.services.send_request(client, sequence, request)

    def send_response(self, srv: Any, request_id: Any, response: Any) -> None:
        self.services.send_response(srv, request_id, response)

    def service_is_ready(self, client: Any) -> bool:
        return self.services.service_is_ready(client)

    # data
    def publish(self, pub: Endpoint, msg: Any) -> None:
        writer = self.writers.get(pub)
        if writer is None:
            return
        ret = write_cdr(writer, padded(cdr.serialize(msg, pub.msg_type.__msgtype__)))
        if ret < 0:
            raise DDSException(ret, f'writing to {pub.topic_name}')

    def receive(self) -> None:
        """Take every sample that arrived, in subscription order, into the context's queue."""
        if not self.waitset.wait(0):  # one call answers "anything at all?"
            return
        enqueue = self.context.enqueue
        for sub, (reader, _) in list(self.readers.items()):
            ros_type = sub.msg_type.__msgtype__
            while True:
                samples = take_cdr(reader, _ANY, _TAKE_BATCH)
                if isinstance(samples, int):
                    raise DDSException(samples, f'taking from {sub.topic_name}')
                for payload, info in samples:
                    if info.valid_data:
                        enqueue(sub, cdr.deserialize(payload, ros_type))
                if len(samples) < _TAKE_BATCH:
                    break
        self.services.receive()

    def wait(self, timeout_sec: float | None) -> bool:
        """Block until a sample arrives (True) or timeout_sec passes (False; None: no limit)."""
        timeout_ns = _INFINITE_NS if timeout_sec is None else max(0, int(timeout_sec * 1e9))
        triggered = self.waitset.wait(timeout_ns)
        if self.wakeup.read():
            self.wakeup.take()
        return triggered > 0

    def wake(self) -> None:
        """Make a wait() in another thread return (shutdown, a signal)."""
        self.wakeup.set(True)

    # graph
    def matched_subscriptions(self, pub: Endpoint) -> int:
        writer = self.writers.get(pub)
        return writer.get_publication_matched_status().current_count if writer is not None else 0

    def matched_publications(self, sub: Endpoint) -> int:
        entry = self.readers.get(sub)
        return entry[0].get_subscription_matched_status().current_count if entry is not None else 0

    def endpoints(self, topic: str, kind: TopicEndpointTypeEnum) -> list[TopicEndpointInfo]:
        return self.graph.endpoints(dds_topic_name(topic), kind)

    def node_names(self) -> list[tuple[str, str]]:
        return self.graph.node_names()

    def endpoint_guid(self, entity: Any) -> uuid.UUID | None:
        """Return the GUID of a publisher's writer or a subscription's reader (its rmw GID)."""
        if entity in self.writers:
            return self.writers[entity].get_guid()
        if entity in self.readers:
            return self.readers[entity][0].get_guid()
        return None

    def shutdown(self) -> None:
        """Delete the participant and every entity under it; remote nodes see them leave."""
        self.readers.clear()
        self.writers.clear()
        self.services.pairs.clear()
        self.topics.clear()
        delete_entity(self.participant)
