"""
Services over DDS as rmw_cyclonedds carries them (rmw_node.cpp, serdata.cpp).

A service `/ns/node/get_parameters` is a request topic `rq/ns/node/get_parametersRequest` and a
reply topic `rr/ns/node/get_parametersReply`, typed `<pkg>::srv::dds_::<Srv>_Request_` and
`_Response_`. Each request and reply carries a 16-byte header before its fields: the client's
request writer instance handle (uint64) and the request's sequence number (int64); the server
copies it into the reply and a client keeps only replies carrying its own handle. The USER_DATA of
a service's reader and writer says `serviceid=<id>;`, a client's `clientid=<id>;`: a client is
ready when a matched request reader and reply writer share a service id, and a server answers once
the client's reply reader is matched (up to 100 ms, as rmw_send_response waits).
"""

from __future__ import annotations

from dataclasses import dataclass
import itertools
import logging
import struct
import time
from typing import Any

from cloth_bench_ros.data import messages as cdr
from cloth_bench_ros.runtime.dds.cyclone_private import take_cdr, write_cdr
from cloth_bench_ros.runtime.dds.qos import endpoint_qos
from cloth_bench_ros.runtime.messages import with_numpy_arrays
from cyclonedds.core import (
    DDSException,
    InstanceState,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader

REQUEST_PREFIX, REPLY_PREFIX = 'rq', 'rr'  # rmw_cyclonedds namespace_prefix.hpp
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any
_HEADER = struct.Struct('<Qq')  # client's writer handle, sequence number (little-endian CDR)
_REPLY_READER_WAIT_S = 0.1
_log = logging.getLogger('cloth_bench_ros.runtime')


def request_topic(service: str) -> str:
    return f'{REQUEST_PREFIX}{service}Request'


def reply_topic(service: str) -> str:
    return f'{REPLY_PREFIX}{service}Reply'


def endpoint_id(participant_guid: bytes, counter: int) -> str:
    """rmw_cyclonedds' client/service id: the participant's GUID prefix and a counter, in hex."""
    data = participant_guid[:12] + counter.to_bytes(4, 'big')
    return f'{data[0]:02x}' + ''.join(f'.{b:x}' for b in data[1:])


def _user_data_key(endpoint: Any, key: str) -> str | None:
    """Return `key`'s value in a discovered endpoint's USER_DATA (`k=v;` pairs), or None."""
    user_data = endpoint.qos[Policy.Userdata] if endpoint is not None else None
    if user_data is None:
        return None
    for pair in user_data.data.decode(errors='replace').split(';'):
        name, _, value = pair.partition('=')
        if name == key:
            return value
    return None


def with_header(payload: bytes, guid: int, sequence: int) -> bytes:
    """Insert the request header after a CDR payload's 4-byte encapsulation header."""
    return payload[:4] + _HEADER.pack(guid, sequence) + payload[4:]


def split_header(payload: bytes) -> tuple[int, int, bytes]:
    """Return (guid, sequence, the payload without the header); ValueError if too short."""
    if len(payload) < 4 + _HEADER.size:
        raise ValueError('a request or reply shorter than its header')
    guid, sequence = _HEADER.unpack_from(payload, 4)
    return guid, sequence, payload[:4] + payload[4 + _HEADER.size:]


@dataclass
class _Pair:
    """The reader and writer of one service (requests in, replies out) or client (the reverse)."""

    reader: DataReader
    condition: ReadCondition
    writer: DataWriter
    handle: int  # the writer's instance handle: a client's id in the request header
    in_type: str  # ROS type of what the reader takes
    out_type: str
    is_service: bool


class DdsServices:
    """The services and clients of one DdsTransport."""

    def __init__(self, transport: Any) -> None:
        self.transport = transport
        self.pairs: dict[Any, _Pair] = {}
        self._ids = itertools.count(1)
        # One wait(0) answers "any request or reply at all?" (the transport's wait set, which
        # the executor blocks on, holds the same conditions).
        self.waitset = WaitSet(transport.participant)

    def add(self, entity: Any, is_service: bool) -> None:
        srv = entity.srv_type.__srvtype__
        request, reply = srv + '_Request', srv + '_Response'
        key = 'serviceid' if is_service else 'clientid'
        guid = self.transport.participant.get_guid().bytes
        user_data = f'{key}={endpoint_id(guid, next(self._ids))};'
        in_topic, in_type, out_topic, out_type = (
            (request_topic(entity.service_name), request, reply_topic(entity.service_name), reply)
            if is_service
            else (
                reply_topic(entity.service_name),
                reply,
                request_topic(entity.service_name),
                request,
            )
        )
        participant = self.transport.participant
        reader = DataReader(
            participant,
            self.transport.topic(in_topic, in_type),
            qos=endpoint_qos(entity.qos, in_type, user_data=user_data),
        )
        writer = DataWriter(
            participant,
            self.transport.topic(out_topic, out_type),
            qos=endpoint_qos(entity.qos, out_type, user_data=user_data),
        )
        condition = ReadCondition(reader, _ANY)
        self.transport.waitset.attach(condition)
        self.waitset.attach(condition)
        self.pairs[entity] = _Pair(
            reader,
            condition,
            writer,
            writer.get_instance_handle() % 2**64,
            in_type,
            out_type,
            is_service,
        )
        self.transport.graph_changed(entity.node)

    def remove(self, entity: Any) -> None:
        pair = self.pairs.pop(entity, None)
        if pair is not None:
            self.transport.waitset.detach(pair.condition)
            self.waitset.detach(pair.condition)
            for dds_entity in (pair.condition, pair.reader, pair.writer):
                self.transport.dispose(dds_entity)
            self.transport.graph_changed(entity.node)

    def guids(self, node: Any) -> tuple[list, list]:
        """Return the node's service/client readers' and writers' GUIDs (ros_discovery_info)."""
        pairs = [p for e, p in self.pairs.items() if e.node is node]
        return [p.reader.get_guid() for p in pairs], [p.writer.get_guid() for p in pairs]

    def receive(self) -> None:
        """Queue requests for services, and replies to this process's clients for them."""
        if not self.waitset.wait(0):
            return
        enqueue = self.transport.context.enqueue
        for entity, pair in list(self.pairs.items()):
            if not pair.condition.triggered:
                continue
            samples = take_cdr(pair.reader, _ANY, 64)
            if isinstance(samples, int):
                raise DDSException(samples, f'taking from {entity.service_name}')
            for payload, info in samples:
                if not info.valid_data:
                    continue
                try:
                    guid, sequence, body = split_header(payload)
                    message = cdr.deserialize(body, pair.in_type)
                except Exception as exc:  # e.g. a Fast DDS client: no header in the payload
                    _log.warning(
                        '%s: dropped a sample that does not parse (%s)', entity.service_name, exc
                    )
                    continue
                if pair.is_service:
                    enqueue(entity, ((guid, sequence, info.publication_handle), message))
                elif guid == pair.handle:  # a client keeps only the replies to its own requests
                    enqueue(entity, (sequence, message))

    def send_request(self, client: Any, sequence: int, request: Any) -> None:
        pair = self.pairs[client]
        payload = cdr.serialize(with_numpy_arrays(request, pair.out_type), pair.out_type)
        self._write(pair, client, with_header(payload, pair.handle, sequence))

    def send_response(self, srv: Any, request_id: tuple[int, int, int], response: Any) -> None:
        """Answer a request once its client's reply reader is matched; drop it if it is gone."""
        guid, sequence, request_writer = request_id
        pair = self.pairs.get(srv)
        if pair is None:
            return
        end = time.monotonic() + _REPLY_READER_WAIT_S
        while (present := self._client_present(pair, request_writer)) is None:
            if time.monotonic() >= end:
                _log.warning(
                    "%s: the client's reply reader never matched; reply dropped", srv.service_name
                )
                return
            time.sleep(0.01)
        if present:
            payload = cdr.serialize(with_numpy_arrays(response, pair.out_type), pair.out_type)
            self._write(pair, srv, with_header(payload, guid, sequence))

    def service_is_ready(self, client: Any) -> bool:
        """rmw_service_server_is_available: a request reader and reply writer of one service."""
        pair = self.pairs.get(client)
        if pair is None:
            return False
        readers = [
            pair.writer.get_matched_subscription_data(h)
            for h in pair.writer.get_matched_subscriptions()
        ]
        writers = [
            pair.reader.get_matched_publication_data(h)
            for h in pair.reader.get_matched_publications()
        ]
        ids = {_user_data_key(r, 'serviceid') for r in readers} - {None}
        if not ids:  # servers that announce no id: matches on both topics suffice
            return bool(readers) and bool(writers)
        return any(_user_data_key(w, 'serviceid') in ids for w in writers)

    def _client_present(self, pair: _Pair, request_writer: int) -> bool | None:
        """Return True if the reply reader matched, False if the client left, else None."""
        writer = pair.reader.get_matched_publication_data(request_writer)
        if writer is None:
            return False
        client_id = _user_data_key(writer, 'clientid')
        if client_id is None:  # a client without an id: assume all is well (as rmw_cyclonedds)
            return True
        for handle in pair.writer.get_matched_subscriptions():
            reader = pair.writer.get_matched_subscription_data(handle)
            if _user_data_key(reader, 'clientid') == client_id:
                return True
        return None

    @staticmethod
    def _write(pair: _Pair, entity: Any, payload: bytes) -> None:
        ret = write_cdr(pair.writer, payload + b'\0' * (-len(payload) % 4))
        if ret < 0:
            raise DDSException(ret, f'writing to {entity.service_name}')
