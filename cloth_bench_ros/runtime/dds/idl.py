"""
DDS types of the ROS 2 messages the project exchanges, as rosidl's IDL maps their .msg files.

rosidl turns `pkg/msg/Type.msg` into IDL (`byte` -> `octet`, `char` -> `uint8`, `float64` ->
`double`, `T[]` -> `sequence<T>`, `T[N]` -> `T name[N]`, `string<=N` -> `string<N>`), and the DDS
type is `pkg::msg::dds_::Type_` (rmw_cyclonedds' naming). Declaring the same structure here makes
the XTypes type information that Cyclone exchanges describe the types ROS 2 generates, so a reader
declared from ROS 2's IDL matches these writers. The payload itself never goes through these
classes: the transport writes and reads rosbags' CDR bytes (see transport.py).
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t


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


# builtin_interfaces, std_msgs, rosgraph_msgs


@dataclass
class Time_(IdlStruct, typename='builtin_interfaces::msg::dds_::Time_'):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Header_(IdlStruct, typename='std_msgs::msg::dds_::Header_'):
    stamp: Time_ = field(default_factory=Time_)
    frame_id: str = ''


@dataclass
class String_(IdlStruct, typename='std_msgs::msg::dds_::String_'):
    data: str = ''


@dataclass
class MultiArrayDimension_(IdlStruct, typename='std_msgs::msg::dds_::MultiArrayDimension_'):
    label: str = ''
    size: t.uint32 = 0
    stride: t.uint32 = 0


@dataclass
class MultiArrayLayout_(IdlStruct, typename='std_msgs::msg::dds_::MultiArrayLayout_'):
    dim: t.sequence[MultiArrayDimension_] = field(default_factory=list)
    data_offset: t.uint32 = 0


@dataclass
class Float64MultiArray_(IdlStruct, typename='std_msgs::msg::dds_::Float64MultiArray_'):
    layout: MultiArrayLayout_ = field(default_factory=MultiArrayLayout_)
    data: t.sequence[t.float64] = field(default_factory=list)


@dataclass
class Clock_(IdlStruct, typename='rosgraph_msgs::msg::dds_::Clock_'):
    clock: Time_ = field(default_factory=Time_)


# geometry_msgs


@dataclass
class Point_(IdlStruct, typename='geometry_msgs::msg::dds_::Point_'):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Quaternion_(IdlStruct, typename='geometry_msgs::msg::dds_::Quaternion_'):
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0
    w: t.float64 = 1.0


@dataclass
class Pose_(IdlStruct, typename='geometry_msgs::msg::dds_::Pose_'):
    position: Point_ = field(default_factory=Point_)
    orientation: Quaternion_ = field(default_factory=Quaternion_)


@dataclass
class PoseArray_(IdlStruct, typename='geometry_msgs::msg::dds_::PoseArray_'):
    header: Header_ = field(default_factory=Header_)
    poses: t.sequence[Pose_] = field(default_factory=list)


# sensor_msgs


@dataclass
class PointField_(IdlStruct, typename='sensor_msgs::msg::dds_::PointField_'):
    name: str = ''
    offset: t.uint32 = 0
    datatype: t.uint8 = 0
    count: t.uint32 = 0


@dataclass
class PointCloud2_(IdlStruct, typename='sensor_msgs::msg::dds_::PointCloud2_'):
    header: Header_ = field(default_factory=Header_)
    height: t.uint32 = 0
    width: t.uint32 = 0
    fields: t.sequence[PointField_] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: t.uint32 = 0
    row_step: t.uint32 = 0
    data: t.sequence[t.uint8] = field(default_factory=list)
    is_dense: bool = False


# diagnostic_msgs (DiagnosticStatus.level is `byte` in the .msg: `octet` in IDL)


@dataclass
class KeyValue_(IdlStruct, typename='diagnostic_msgs::msg::dds_::KeyValue_'):
    key: str = ''
    value: str = ''


@dataclass
class DiagnosticStatus_(IdlStruct, typename='diagnostic_msgs::msg::dds_::DiagnosticStatus_'):
    level: t.byte = 0
    name: str = ''
    message: str = ''
    hardware_id: str = ''
    values: t.sequence[KeyValue_] = field(default_factory=list)


@dataclass
class DiagnosticArray_(IdlStruct, typename='diagnostic_msgs::msg::dds_::DiagnosticArray_'):
    header: Header_ = field(default_factory=Header_)
    status: t.sequence[DiagnosticStatus_] = field(default_factory=list)


# rcl_interfaces: what every node publishes (/rosout, /parameter_events)


@dataclass
class Log_(IdlStruct, typename='rcl_interfaces::msg::dds_::Log_'):
    stamp: Time_ = field(default_factory=Time_)
    level: t.uint8 = 0
    name: str = ''
    msg: str = ''
    file: str = ''
    function: str = ''
    line: t.uint32 = 0


@dataclass
class ParameterValue_(IdlStruct, typename='rcl_interfaces::msg::dds_::ParameterValue_'):
    type: t.uint8 = 0  # noqa: A003 (the .msg's field name)
    bool_value: bool = False
    integer_value: t.int64 = 0
    double_value: t.float64 = 0.0
    string_value: str = ''
    byte_array_value: t.sequence[t.byte] = field(default_factory=list)
    bool_array_value: t.sequence[bool] = field(default_factory=list)
    integer_array_value: t.sequence[t.int64] = field(default_factory=list)
    double_array_value: t.sequence[t.float64] = field(default_factory=list)
    string_array_value: t.sequence[str] = field(default_factory=list)


@dataclass
class Parameter_(IdlStruct, typename='rcl_interfaces::msg::dds_::Parameter_'):
    name: str = ''
    value: ParameterValue_ = field(default_factory=ParameterValue_)


@dataclass
class ParameterEvent_(IdlStruct, typename='rcl_interfaces::msg::dds_::ParameterEvent_'):
    stamp: Time_ = field(default_factory=Time_)
    node: str = ''
    new_parameters: t.sequence[Parameter_] = field(default_factory=list)
    changed_parameters: t.sequence[Parameter_] = field(default_factory=list)
    deleted_parameters: t.sequence[Parameter_] = field(default_factory=list)


@dataclass
class FloatingPointRange_(IdlStruct, typename='rcl_interfaces::msg::dds_::FloatingPointRange_'):
    from_value: t.float64 = 0.0
    to_value: t.float64 = 0.0
    step: t.float64 = 0.0


@dataclass
class IntegerRange_(IdlStruct, typename='rcl_interfaces::msg::dds_::IntegerRange_'):
    from_value: t.int64 = 0
    to_value: t.int64 = 0
    step: t.uint64 = 0


@dataclass
class ParameterDescriptor_(
    IdlStruct, typename='rcl_interfaces::msg::dds_::ParameterDescriptor_'
):
    name: str = ''
    type: t.uint8 = 0  # noqa: A003 (the .msg's field name)
    description: str = ''
    additional_constraints: str = ''
    read_only: bool = False
    dynamic_typing: bool = False
    floating_point_range: t.sequence[FloatingPointRange_, 1] = field(default_factory=list)
    integer_range: t.sequence[IntegerRange_, 1] = field(default_factory=list)


@dataclass
class ListParametersResult_(
    IdlStruct, typename='rcl_interfaces::msg::dds_::ListParametersResult_'
):
    names: t.sequence[str] = field(default_factory=list)
    prefixes: t.sequence[str] = field(default_factory=list)


@dataclass
class SetParametersResult_(IdlStruct, typename='rcl_interfaces::msg::dds_::SetParametersResult_'):
    successful: bool = False
    reason: str = ''


# rcl_interfaces/srv: the parameter services. rmw_cyclonedds writes a request header (the client's
# request writer instance handle and a sequence number) before the fields; these types say so.


@dataclass
class DescribeParameters_Request_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::DescribeParameters_Request_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    names: t.sequence[str] = field(default_factory=list)


@dataclass
class DescribeParameters_Response_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::DescribeParameters_Response_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    descriptors: t.sequence[ParameterDescriptor_] = field(default_factory=list)


@dataclass
class GetParameters_Request_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::GetParameters_Request_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    names: t.sequence[str] = field(default_factory=list)


@dataclass
class GetParameters_Response_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::GetParameters_Response_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    values: t.sequence[ParameterValue_] = field(default_factory=list)


@dataclass
class GetParameterTypes_Request_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::GetParameterTypes_Request_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    names: t.sequence[str] = field(default_factory=list)


@dataclass
class GetParameterTypes_Response_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::GetParameterTypes_Response_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    types: t.sequence[t.uint8] = field(default_factory=list)


@dataclass
class ListParameters_Request_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::ListParameters_Request_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    prefixes: t.sequence[str] = field(default_factory=list)
    depth: t.uint64 = 0


@dataclass
class ListParameters_Response_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::ListParameters_Response_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    result: ListParametersResult_ = field(default_factory=ListParametersResult_)


@dataclass
class SetParameters_Request_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::SetParameters_Request_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    parameters: t.sequence[Parameter_] = field(default_factory=list)


@dataclass
class SetParameters_Response_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::SetParameters_Response_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    results: t.sequence[SetParametersResult_] = field(default_factory=list)


@dataclass
class SetParametersAtomically_Request_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::SetParametersAtomically_Request_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    parameters: t.sequence[Parameter_] = field(default_factory=list)


@dataclass
class SetParametersAtomically_Response_(
    IdlStruct, typename='rcl_interfaces::srv::dds_::SetParametersAtomically_Response_'
):
    client_guid: t.uint64 = 0
    sequence_number: t.int64 = 0
    result: SetParametersResult_ = field(default_factory=SetParametersResult_)


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


DDS_TYPES: dict[str, type] = {
    'builtin_interfaces/msg/Time': Time_,
    'std_msgs/msg/Header': Header_,
    'std_msgs/msg/String': String_,
    'std_msgs/msg/MultiArrayDimension': MultiArrayDimension_,
    'std_msgs/msg/MultiArrayLayout': MultiArrayLayout_,
    'std_msgs/msg/Float64MultiArray': Float64MultiArray_,
    'rosgraph_msgs/msg/Clock': Clock_,
    'geometry_msgs/msg/Point': Point_,
    'geometry_msgs/msg/Quaternion': Quaternion_,
    'geometry_msgs/msg/Pose': Pose_,
    'geometry_msgs/msg/PoseArray': PoseArray_,
    'sensor_msgs/msg/PointField': PointField_,
    'sensor_msgs/msg/PointCloud2': PointCloud2_,
    'diagnostic_msgs/msg/KeyValue': KeyValue_,
    'diagnostic_msgs/msg/DiagnosticStatus': DiagnosticStatus_,
    'diagnostic_msgs/msg/DiagnosticArray': DiagnosticArray_,
    'rcl_interfaces/msg/Log': Log_,
    'rcl_interfaces/msg/ParameterValue': ParameterValue_,
    'rcl_interfaces/msg/Parameter': Parameter_,
    'rcl_interfaces/msg/ParameterEvent': ParameterEvent_,
    'rmw_dds_common/msg/ParticipantEntitiesInfo': ParticipantEntitiesInfo_,
    'rcl_interfaces/srv/DescribeParameters_Request': DescribeParameters_Request_,
    'rcl_interfaces/srv/DescribeParameters_Response': DescribeParameters_Response_,
    'rcl_interfaces/srv/GetParameters_Request': GetParameters_Request_,
    'rcl_interfaces/srv/GetParameters_Response': GetParameters_Response_,
    'rcl_interfaces/srv/GetParameterTypes_Request': GetParameterTypes_Request_,
    'rcl_interfaces/srv/GetParameterTypes_Response': GetParameterTypes_Response_,
    'rcl_interfaces/srv/ListParameters_Request': ListParameters_Request_,
    'rcl_interfaces/srv/ListParameters_Response': ListParameters_Response_,
    'rcl_interfaces/srv/SetParameters_Request': SetParameters_Request_,
    'rcl_interfaces/srv/SetParameters_Response': SetParameters_Response_,
    'rcl_interfaces/srv/SetParametersAtomically_Request': SetParametersAtomically_Request_,
    'rcl_interfaces/srv/SetParametersAtomically_Response': SetParametersAtomically_Response_,
}


def dds_type(ros_type: str) -> type:
    """Return the DDS type class of a ROS type name; ValueError for a type not carried."""
    try:
        return DDS_TYPES[ros_type]
    except KeyError:
        raise ValueError(f'message type {ros_type} has no DDS type in cloth_bench_ros') from None
