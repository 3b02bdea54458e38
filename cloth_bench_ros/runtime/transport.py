"""
How the embedded runtime moves messages: intra-process (the default) or DDS (runtime/dds/).

A Context owns one transport. Publishers and subscriptions register with it; `publish` hands it a
message; the executor calls `receive` to move arrived messages into the context's queue and `wait`
to block until one may have arrived; the graph queries (`endpoints`, matched counts) answer what
rclpy's get_publishers_info_by_topic / get_subscriptions_info_by_topic and
Publisher.get_subscription_count answer.

CLOTH_BENCH_TRANSPORT=intra|dds chooses it where the caller does not: the node console scripts
default to dds (one process per node), `cloth-bench run` and sweeps to intra.
"""

from __future__ import annotations

import os
import time
from typing import Any, Protocol

from cloth_bench_ros.errors import InputError
from cloth_bench_ros.runtime.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from cloth_bench_ros.runtime.topic_endpoint_info import TopicEndpointInfo, TopicEndpointTypeEnum

TRANSPORTS = ('intra', 'dds')


class Endpoint(Protocol):
    """What a transport uses of a publisher or subscription of runtime/embedded.py."""

    node: Any
    msg_type: Any  # a message class (rclpy-like, with __msgtype__)
    topic_name: str
    qos: QoSProfile


def transport_choice(default: str) -> str:
    """Return CLOTH_BENCH_TRANSPORT if set (intra or dds), else `default`."""
    choice = os.environ.get('CLOTH_BENCH_TRANSPORT', '').strip().lower() or default
    if choice not in TRANSPORTS:
        raise InputError(
            f'CLOTH_BENCH_TRANSPORT: unknown transport {choice!r} (valid: intra, dds)'
        )
    return choice


def compatible(writer: QoSProfile, reader: QoSProfile) -> bool:
    """Return whether DDS matches a writer and a reader (the reader asks no more than offered)."""
    return not (
        (
            writer.reliability == ReliabilityPolicy.BEST_EFFORT
            and reader.reliability == ReliabilityPolicy.RELIABLE
        )
        or (
            writer.durability == DurabilityPolicy.VOLATILE
            and reader.durability == DurabilityPolicy.TRANSIENT_LOCAL
        )
    )


class IntraProcessTransport:
    """
    Nodes of one context in one process: one FIFO, callbacks in publish order.

    QoS as DDS applies it: a writer reaches only the readers it is compatible with, and a
    keep-last reader keeps its newest `depth` messages (keep-all readers lose nothing).
    """

    name = 'intra'

    def __init__(self, context: Any) -> None:
        self.context = context
        self._readers: dict[int, list] = {}  # id(publisher) -> its matched subscriptions

    def add_publisher(self, pub: Endpoint) -> None:
        self.context.publishers.setdefault(pub.topic_name, []).append(pub)

    def remove_publisher(self, pub: Endpoint) -> None:
        pubs = self.context.publishers.get(pub.topic_name, [])
        if pub in pubs:
            pubs.remove(pub)
        self._readers.pop(id(pub), None)

    def add_subscription(self, sub: Endpoint) -> None:
        self._readers.clear()  # matched once per publisher, again after any change of readers
        self.context.subscriptions.setdefault(sub.topic_name, []).append(sub)
        if sub.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:  # late joiners get the history
            for pub in self.context.publishers.get(sub.topic_name, ()):
                if compatible(pub.qos, sub.qos):
                    for msg in pub._history:
                        self.context.enqueue(sub, msg)

    def remove_subscription(self, sub: Endpoint) -> None:
        self._readers.clear()
        subs = self.context.subscriptions.get(sub.topic_name, [])
        if sub in subs:
            subs.remove(sub)

    def publish(self, pub: Any, msg: Any) -> None:
        if pub.qos.durability == DurabilityPolicy.TRANSIENT_LOCAL:
            pub._history.append(msg)
        readers = self._readers.get(id(pub))
        if readers is None:
            subs = self.context.subscriptions.get(pub.topic_name, ())
            readers = self._readers[id(pub)] = [s for s in subs if compatible(pub.qos, s.qos)]
        enqueue = self.context.enqueue
        for sub in readers:
            enqueue(sub, msg)

    # services: a request goes to every server of the name and type, the reply to its client
    def add_service(self, srv: Any) -> None:
        self.context.services.setdefault(srv.service_name, []).append(srv)

    def remove_service(self, srv: Any) -> None:
        if srv in self.context.services.get(srv.service_name, ()):
            self.context.services[srv.service_name].remove(srv)

    def add_client(self, client: Any) -> None:
        self.context.clients.setdefault(client.service_name, []).append(client)

    def remove_client(self, client: Any) -> None:
        if client in self.context.clients.get(client.service_name, ()):
            self.context.clients[client.service_name].remove(client)

    def _servers(self, client: Any) -> list[Any]:
        servers = self.context.services.get(client.service_name, ())
        return [s for s in servers if s.srv_type.__srvtype__ == client.srv_type.__srvtype__]

    def send_request(self, client: Any, sequence: int, request: Any) -> None:
        for srv in self._servers(client):
            self.context.enqueue(srv, ((client, sequence), request))

    def send_response(self, srv: Any, request_id: Any, response: Any) -> None:
        client, sequence = request_id
        if client in self.context.clients.get(srv.service_name, ()):  # a destroyed client: dropped
            self.context.enqueue(client, (sequence, response))

    def service_is_ready(self, client: Any) -> bool:
        return bool(self._servers(client))

    def matched_subscriptions(self, pub: Endpoint) -> int:
        subs = self.context.subscriptions.get(pub.topic_name, ())
        return sum(compatible(pub.qos, sub.qos) for sub in subs)

    def matched_publications(self, sub: Endpoint) -> int:
        pubs = self.context.publishers.get(sub.topic_name, ())
        return sum(compatible(pub.qos, sub.qos) for pub in pubs)

    def endpoints(self, topic: str, kind: TopicEndpointTypeEnum) -> list[TopicEndpointInfo]:
        table = (
            self.context.publishers
            if kind == TopicEndpointTypeEnum.PUBLISHER
            else self.context.subscriptions
        )
        return [
            TopicEndpointInfo(
                e.node.get_name(),
                e.node.get_namespace(),
                e.msg_type.__msgtype__,
                kind,
                qos_profile=e.qos,
            )
            for e in table.get(topic, ())
        ]

    def node_names(self) -> list[tuple[str, str]]:
        return [(n.get_name(), n.get_namespace()) for n in self.context.nodes]

    def graph_changed(self, node: Any) -> None:
        """Nothing to announce: every node of the graph is in this context."""

    def receive(self) -> None:
        """Nothing to fetch: publish() queues directly."""

    def wait(self, timeout_sec: float | None) -> bool:
        """Nothing can arrive while waiting in one process: sleep; False (no message came)."""
        if timeout_sec:
            time.sleep(timeout_sec)
        return False

    def shutdown(self) -> None:
        """No resources to release."""
