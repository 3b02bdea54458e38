"""
Reading ros_discovery_info samples of any ROS 2 distribution: 16-byte or 24-byte graph GIDs.

rmw_dds_common's Gid is `char[16] data` from Iron on and `char[24] data` in Humble (the GUID's 16
bytes, then zeros). A typed reader of one layout misreads the other: read with the 16-byte type, a
Humble sample has no nodes, so every endpoint of a Humble node would stay
`_NODE_NAME_UNKNOWN_`. The raw CDR is parsed here with either size, and the one that reads the
whole sample is kept; GIDs come back as their first 16 bytes, which is what an endpoint's GUID is.
"""

from __future__ import annotations

import struct

from cloth_bench_ros.runtime.dds.idl import Gid_, NodeEntitiesInfo_, ParticipantEntitiesInfo_

GID_SIZES = (16, 24)  # Iron and later, Humble
_MAX_NAME = 256  # NodeEntitiesInfo's names are string<256>
_MAX_COUNT = 1 << 16


class _Cdr:
    """A cursor over XCDR1 bytes (after the 4-byte encapsulation header)."""

    def __init__(self, payload: bytes) -> None:
        if len(payload) < 4 or payload[0] != 0 or payload[1] not in (0, 1):
            raise ValueError('not a plain CDR sample')
        self.order = '<' if payload[1] == 1 else '>'
        self.data, self.pos = payload[4:], 0

    def take(self, size: int) -> bytes:
        if self.pos + size > len(self.data):
            raise ValueError('sample ends early')
        chunk = self.data[self.pos:self.pos + size]
        self.pos += size
        return chunk

    def count(self, limit: int = _MAX_COUNT) -> int:
        self.pos += -self.pos % 4
        (value,) = struct.unpack(self.order + 'I', self.take(4))
        if value > limit:
            raise ValueError('implausible length')
        return value

    def string(self) -> str:
        size = self.count(_MAX_NAME + 1)
        raw = self.take(size)
        if not raw or raw[-1] != 0:
            raise ValueError('string without its terminating zero')
        return raw[:-1].decode()


def _parse(payload: bytes, gid_size: int) -> ParticipantEntitiesInfo_:
    cdr = _Cdr(payload)

    def gid() -> Gid_:
        return Gid_(data=list(cdr.take(gid_size)[:16]))

    participant = gid()
    nodes = []
    for _ in range(cdr.count()):
        namespace, name = cdr.string(), cdr.string()
        readers = [gid() for _ in range(cdr.count())]
        writers = [gid() for _ in range(cdr.count())]
        nodes.append(NodeEntitiesInfo_(namespace, name, readers, writers))
    if len(cdr.data) - cdr.pos >= 4:  # more than padding left: the other layout
        raise ValueError('bytes left over')
    return ParticipantEntitiesInfo_(gid=participant, node_entities_info_seq=nodes)


def parse_participant_entities(payload: bytes) -> ParticipantEntitiesInfo_:
    """Return a ros_discovery_info sample read with the Gid size that fits (ValueError: none)."""
    errors = []
    for size in GID_SIZES:
        try:
            return _parse(bytes(payload), size)
        except (ValueError, UnicodeDecodeError, struct.error) as exc:
            errors.append(f'{size}-byte GIDs: {exc}')
    raise ValueError('ros_discovery_info sample not readable: ' + '; '.join(errors))
