"""
DDS types of the ROS 2 messages the project exchanges, as rosidl's IDL maps their .msg files.

rosidl turns `pkg/msg/Type.msg` into IDL (`byte` -> `octet`, `char` -> `uint8`, `float64` ->
`double`, `T[]` -> `sequence<T>`, `T[<=N]` -> `sequence<T, N>`, `T[N]` -> `T name[N]`,
`string<=N` -> `string<N>`), and the DDS type is `pkg::msg::dds_::Type_` (rmw_cyclonedds'
naming); a service's request and response start with rmw_cyclonedds' request header (the
client's writer GUID as a uint64 and a sequence number). `dds_type` builds each struct from the
project's one type store (data/messages.py) that way, so the XTypes type information Cyclone
exchanges describes the types ROS 2 generates and a reader declared from ROS 2's IDL matches these
writers (test/test_idl.py compares it with structs written out by hand). The payload itself never
goes through these classes: the transport writes and reads the type store's CDR bytes.
"""

from dataclasses import dataclass, field
import types
from typing import Any

from cloth_bench_ros.data.messages import TYPESTORE
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from rosbags.interfaces import Nodetype


def dds_type_name(ros_type: str) -> str:
    """`sensor_msgs/msg/PointCloud2` -> `sensor_msgs::msg::dds_::PointCloud2_` (rmw_cyclonedds)."""
    package, kind, name = ros_type.split('/')
    return f'{package}::{kind}::dds_::{name}_'


def ros_type_name(dds_type: str) -> str:
    """Return the inverse of dds_type_name; other DDS type names come back unchanged."""
    parts = dds_type.split('::')
    if len(parts) == 4 and parts[2] == 'dds_' and parts[3].endswith('_'):
        return f'{parts[0]}/{parts[1]}/{parts[3][:-1]}'
    return dds_type


# rmw_dds_common: the graph information of ros_discovery_info (Gid is `char[16] data`)


@dataclass
class Gid_(IdlStruct, typename='rmw_dds_common::msg::dds_::Gid_'):
    data: t.array[t.uint8, 16] = field(default_factory=lambda: [0] * 16)


@dataclass
class NodeEntitiesInfo_(IdlStruct, typename='rmw_dds_common::msg::dds_::NodeEntitiesInfo_'):
    node_namespace: t.bounded_str[256] = ''
    node_name: t.bounded_str[256] = ''
    reader_gid_seq: t.sequence[Gid_] = field(default_factory=list)
    writer_gid_seq: t.sequence[Gid_] = field(default_factory=list)


@dataclass
class ParticipantEntitiesInfo_(
    IdlStruct, typename='rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_'
):
    gid: Gid_ = field(default_factory=Gid_)
    node_entities_info_seq: t.sequence[NodeEntitiesInfo_] = field(default_factory=list)


_BASE_TYPES: dict[str, Any] = {
    'bool': bool,
    'byte': t.byte,
    'char': t.uint8,
    'float32': t.float32,
    'float64': t.float64,
    'int8': t.int8,
    'uint8': t.uint8,
    'int16': t.int16,
    'uint16': t.uint16,
    'int32': t.int32,
    'uint32': t.uint32,
    'int64': t.int64,
    'uint64': t.uint64,
}
# The graph's types as Jazzy's rmw_dds_common declares them (a 16-byte Gid; the Humble type
# store's is 24 bytes, which graph.py reads raw): these are not generated.
_GRAPH_TYPES = {
    'rmw_dds_common/msg/Gid': Gid_,
    'rmw_dds_common/msg/NodeEntitiesInfo': NodeEntitiesInfo_,
    'rmw_dds_common/msg/ParticipantEntitiesInfo': ParticipantEntitiesInfo_,
}
_generated: dict[str, type] = {}


def _annotation(node: Any) -> Any:
    """Return the cyclonedds annotation of one field (a rosbags node tuple)."""
    kind, detail = node
    if kind == Nodetype.BASE:
        name, bound = detail
        if name == 'string':
            return t.bounded_str[bound] if bound else str
        return _BASE_TYPES[name]
    if kind == Nodetype.NAME:
        return dds_type(detail)
    inner, size = detail
    if kind == Nodetype.ARRAY:
        return t.array[_annotation(inner), size]
    return t.sequence[_annotation(inner), size] if size else t.sequence[_annotation(inner)]


def _struct(ros_type: str) -> type:
    """Return the IdlStruct of a type in the type store, its nested types made first."""
    fields: dict[str, Any] = {}
    if '/srv/' in ros_type:  # rmw_cyclonedds' request header: client GUID, sequence number
        fields.update(client_guid=t.uint64, sequence_number=t.int64)
    for name, node in TYPESTORE.fielddefs[ros_type][1]:
        fields[name] = _annotation(node)
    cls = types.new_class(
        ros_type.rsplit('/', 1)[1] + '_',
        (IdlStruct,),
        {'typename': dds_type_name(ros_type)},
        lambda namespace: namespace.update(__annotations__=fields, __module__=__name__),
    )
    return dataclass(cls)


def dds_type(ros_type: str) -> type:
    """Return the DDS type class of a ROS type name; ValueError for a type not in the store."""
    if ros_type in _GRAPH_TYPES:
        return _GRAPH_TYPES[ros_type]
    if ros_type not in _generated:
        if ros_type not in TYPESTORE.fielddefs:
            raise ValueError(f'message type {ros_type} has no DDS type in cloth_bench_ros')
        _generated[ros_type] = _struct(ros_type)
    return _generated[ros_type]
