"""
The benchmark as four kinds of OS process over real Cyclone DDS, watched by a plain DDS reader.

trajectory_publisher, one simulator per engine, recorder and evaluator run as separate processes
(`python -m cloth_bench_ros.nodes.<node>`, what the console scripts run) on loopback (the session
fixture of conftest.py: interface lo, no multicast, peer 127.0.0.1, a random ROS domain). The
receiving side below uses no project code: its DDS types are written here from the .msg files as
rosidl's IDL maps them (byte -> octet, uint8[] -> sequence<uint8>, ...), and rosbags (not the
project) gives the reference CDR.
"""

from dataclasses import dataclass, field
import os

from cloth_bench_ros.studies.processes import run_processes
from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig
from cyclonedds._clayer import ddspy_take
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

# --- the .msg definitions, as rosidl's IDL and rmw_cyclonedds name them -----------------------


@dataclass
class Time(
    IdlStruct, typename='builtin_interfaces::msg::dds_::Time_'
):  # int32 sec, uint32 nanosec
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Header(IdlStruct, typename='std_msgs::msg::dds_::Header_'):  # Time stamp, string frame_id
    stamp: Time = field(default_factory=Time)
    frame_id: str = ''


@dataclass
class Clock(
    IdlStruct, typename='rosgraph_msgs::msg::dds_::Clock_'
):  # builtin_interfaces/Time clock
    clock: Time = field(default_factory=Time)


@dataclass
class Point(IdlStruct, typename='geometry_msgs::msg::dds_::Point_'):  # float64 x, y, z
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@dataclass
class Quaternion(
    IdlStruct, typename='geometry_msgs::msg::dds_::Quaternion_'
):  # float64 x, y, z, w
    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0
    w: t.float64 = 1.0


@dataclass
class Pose(
    IdlStruct, typename='geometry_msgs::msg::dds_::Pose_'
):  # Point position, Quaternion orientation
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseArray(
    IdlStruct, typename='geometry_msgs::msg::dds_::PoseArray_'
):  # Header header, Pose[] poses
    header: Header = field(default_factory=Header)
    poses: t.sequence[Pose] = field(default_factory=list)


@dataclass
class PointField(IdlStruct, typename='sensor_msgs::msg::dds_::PointField_'):
    name: str = ''  # string name, uint32 offset, uint8 datatype, uint32 count
    offset: t.uint32 = 0
    datatype: t.uint8 = 0
    count: t.uint32 = 0


@dataclass
class PointCloud2(IdlStruct, typename='sensor_msgs::msg::dds_::PointCloud2_'):
    header: Header = field(default_factory=Header)
    height: t.uint32 = 0
    width: t.uint32 = 0
    fields: t.sequence[PointField] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: t.uint32 = 0
    row_step: t.uint32 = 0
    data: t.sequence[t.uint8] = field(default_factory=list)
    is_dense: bool = False


@dataclass
class KeyValue(
    IdlStruct, typename='diagnostic_msgs::msg::dds_::KeyValue_'
):  # string key, string value
    key: str = ''
    value: str = ''


@dataclass
class DiagnosticStatus(IdlStruct, typename='diagnostic_msgs::msg::dds_::DiagnosticStatus_'):
    level: t.byte = 0  # `byte level` in the .msg: octet
    name: str = ''
    message: str = ''
    hardware_id: str = ''
    values: t.sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename='diagnostic_msgs::msg::dds_::DiagnosticArray_'):
    header: Header = field(default_factory=Header)
    status: t.sequence[DiagnosticStatus] = field(default_factory=list)


@dataclass
class PointFieldOctet(IdlStruct, typename='sensor_msgs::msg::dds_::PointField_'):
    """A wrong declaration: `datatype` as octet where rosidl says uint8."""

    name: str = ''
    offset: t.uint32 = 0
    datatype: t.byte = 0
    count: t.uint32 = 0


@dataclass
class PointCloud2Octet(IdlStruct, typename='sensor_msgs::msg::dds_::PointCloud2_'):
    header: Header = field(default_factory=Header)
    height: t.uint32 = 0
    width: t.uint32 = 0
    fields: t.sequence[PointFieldOctet] = field(default_factory=list)
    is_bigendian: bool = False
    point_step: t.uint32 = 0
    row_step: t.uint32 = 0
    data: t.sequence[t.uint8] = field(default_factory=list)
    is_dense: bool = False


@dataclass
class MultiArrayDimension(IdlStruct, typename='std_msgs::msg::dds_::MultiArrayDimension_'):
    label: str = ''
    size: t.uint32 = 0
    stride: t.uint32 = 0


@dataclass
class MultiArrayLayout(IdlStruct, typename='std_msgs::msg::dds_::MultiArrayLayout_'):
    dim: t.sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: t.uint32 = 0


@dataclass
class Float64MultiArray(IdlStruct, typename='std_msgs::msg::dds_::Float64MultiArray_'):
    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: t.sequence[t.float64] = field(default_factory=list)


# --- the run ---------------------------------------------------------------------------------

ENGINES = ['mujoco', 'bullet']
TOPICS = {  # DDS topic: (type, ROS type)
    'rt/cloth_bench/metrics': (DiagnosticArray, 'diagnostic_msgs/msg/DiagnosticArray'),
    'rt/cloth_bench/mujoco/cloud': (PointCloud2, 'sensor_msgs/msg/PointCloud2'),
    'rt/cloth_bench/targets': (PoseArray, 'geometry_msgs/msg/PoseArray'),
    'rt/clock': (Clock, 'rosgraph_msgs/msg/Clock'),
    'rt/cloth_bench/mujoco/frame_metrics': (Float64MultiArray, 'std_msgs/msg/Float64MultiArray'),
    'rt/cloth_bench/mujoco/error_cloud': (PointCloud2, 'sensor_msgs/msg/PointCloud2'),
}
ROSBAGS = get_typestore(Stores.ROS2_HUMBLE)
_ANY = SampleState.Any | ViewState.Any | InstanceState.Any


def _config(bag, out) -> RunConfig:
    return RunConfig(bag=bag, engines=ENGINES, rate_hz=50.0, grid=(6, 8), output_dir=out)


@pytest.fixture(scope='module')
def graph_run(hanging_bag, tmp_path_factory):
    """One four-kinds-of-process run with plain readers on its topics; their raw payloads."""
    participant = DomainParticipant(int(os.environ['ROS_DOMAIN_ID']))
    qos = Qos(Policy.Reliability.Reliable(max_blocking_time=10**9), Policy.History.KeepAll)
    readers = {
        name: DataReader(participant, Topic(participant, name, cls), qos=qos)
        for name, (cls, _) in TOPICS.items()
    }
    wrong = DataReader(
        participant, Topic(participant, 'rt/cloth_bench/bullet/cloud', PointCloud2Octet), qos=qos
    )
    right = DataReader(
        participant, Topic(participant, 'rt/cloth_bench/bullet/cloud', PointCloud2), qos=qos
    )
    summary = run_processes(_config(hanging_bag, tmp_path_factory.mktemp('processes')))
    payloads = {}
    for name, reader in readers.items():
        samples = ddspy_take(reader._ref, _ANY, 100_000)
        payloads[name] = [data for data, info in samples if info.valid_data]
    matched = {
        'wrong': wrong.get_subscription_matched_status().total_count,
        'right': right.get_subscription_matched_status().total_count,
    }
    return summary, payloads, matched


@pytest.mark.slow
def test_four_kinds_of_process_give_the_in_process_metrics(graph_run, hanging_bag, tmp_path):
    summary, _, _ = graph_run
    reference = run_pipeline(_config(hanging_bag, tmp_path / 'in_process'))
    for engine in ENGINES:
        ours, theirs = summary['engines'][engine], reference['engines'][engine]
        assert (ours['CD_d'], ours['HD_d'], ours['L_s']) == (
            theirs['CD_d'],
            theirs['HD_d'],
            theirs['L_s'],
        )
        assert ours['frames_scored'] == theirs['frames_scored'] == 132
        assert ours['step_time']['count'] == theirs['step_time']['count'] == 370  # 7.4 s at 50 Hz
    assert summary['real'] == reference['real']


def _to_rosbags(sample, msgtype: str):
    """Return the rosbags message with the field values a plain Cyclone reader decoded."""
    values = {}
    for name, (kind, detail) in ROSBAGS.fielddefs[msgtype][1]:
        value = getattr(sample, name)
        if kind == 2:  # nested message
            value = _to_rosbags(value, detail)
        elif kind == 4:  # sequence
            (inner_kind, inner), _ = detail
            if inner_kind == 2:
                value = [_to_rosbags(v, inner) for v in value]
            elif inner[0] == 'uint8':
                value = np.array(value, dtype=np.uint8)
            elif inner[0] == 'float64':
                value = np.array(value, dtype=np.float64)
        values[name] = value
    return ROSBAGS.types[msgtype](**values)


def test_a_plain_dds_reader_receives_the_graph_and_its_bytes_are_rosbags_cdr(graph_run):
    summary, payloads, matched = graph_run
    metrics = [DiagnosticArray.deserialize(p) for p in payloads['rt/cloth_bench/metrics']]
    final = {
        s.hardware_id: {kv.key: kv.value for kv in s.values}
        for m in metrics
        for s in m.status
        if s.name.endswith('/summary')
    }
    assert set(final) == set(ENGINES)
    assert float(final['mujoco']['CD_d']) == pytest.approx(
        summary['engines']['mujoco']['CD_d'], rel=1e-12
    )
    clouds = [PointCloud2.deserialize(p) for p in payloads['rt/cloth_bench/mujoco/cloud']]
    assert len(clouds) == 371 and clouds[-1].width == 48 and clouds[-1].header.frame_id == 'world'
    xyz = np.frombuffer(bytes(clouds[-1].data), np.float32).reshape(48, 3)
    assert np.isfinite(xyz).all() and 0.0 < xyz[:, 2].max() < 2.0
    frames = [
        Float64MultiArray.deserialize(p) for p in payloads['rt/cloth_bench/mujoco/frame_metrics']
    ]
    assert len(frames) == 132 and frames[0].layout.dim[0].label == 't,cd,hd,in_window'
    window = [f.data[1] for f in frames if f.data[3] == 1.0]
    assert np.mean(window) == pytest.approx(summary['engines']['mujoco']['CD_d'], rel=1e-12)
    errors = [PointCloud2.deserialize(p) for p in payloads['rt/cloth_bench/mujoco/error_cloud']]
    assert len(errors) == 132 and [f.name for f in errors[0].fields] == ['x', 'y', 'z', 'error']
    for cloud, frame in zip(errors, frames):  # each vertex's error: CD their mean, HD their max
        error = np.frombuffer(bytes(cloud.data), np.float32).reshape(48, 4)[:, 3]
        assert error.max() == pytest.approx(frame.data[2], rel=1e-6)
        assert error.astype(float).mean() == pytest.approx(frame.data[1], rel=1e-5)
    for topic, (cls, msgtype) in TOPICS.items():
        assert payloads[topic], topic
        for payload in payloads[topic][:3] + payloads[topic][-3:]:
            sample = cls.deserialize(payload)
            reference = bytes(ROSBAGS.serialize_cdr(_to_rosbags(sample, msgtype), msgtype))
            padding = payload[len(reference):]
            assert payload[: len(reference)] == reference and padding == bytes(len(padding)), topic
            assert len(payload) % 4 == 0 and len(padding) < 4
            assert payload == sample.serialize().ljust(
                len(payload), b'\0'
            )  # Cyclone's typed writer, too
    # XTypes type information travels: declared with octet where rosidl says uint8, no match
    assert matched == {'wrong': 0, 'right': 1}
