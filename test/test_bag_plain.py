"""Plain rosbag2 recordings: metadata 4-9, split files, hardening, tf, start times, layouts."""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import time

from cloth_bench_ros.core.cleaning import clean, CleaningConfig, CleaningStats, workspace_box
from cloth_bench_ros.data import BagError, BagReader, BagWriter, messages
from cloth_bench_ros.data.alignment import AlignmentError, given_start, targets_start
from cloth_bench_ros.data.messages import POINTCLOUD2, POSE_ARRAY
from cloth_bench_ros.data.replay import plan_replay, ReplayOptions
from cloth_bench_ros.data.tf_buffer import TfBuffer, TransformError
import numpy as np
import pytest
import yaml

POINTS = np.random.default_rng(0).random((40, 3))


def _plain_bag(path: Path, frames: int = 4, first_ns: int = 10**18) -> Path:
    with BagWriter(path) as bag:
        for k in range(frames):
            bag.write_cloud('/points', first_ns + k * 33_333_333, POINTS)
    return path


def _as_version(path: Path, version: int) -> None:
    """Rewrite metadata.yaml in the layout rosbag2 writes at `version`."""
    doc = yaml.safe_load((path / 'metadata.yaml').read_text())
    info = doc['rosbag2_bagfile_information']
    info['version'] = version
    for t in info['topics_with_message_count']:
        meta = t['topic_metadata']
        if version < 9:
            meta['offered_qos_profiles'] = yaml.safe_dump(meta['offered_qos_profiles'])
        if version < 7:
            del meta['type_description_hash']
    for key, since in (('files', 5), ('custom_data', 6), ('ros_distro', 8)):
        if version < since:
            del info[key]
    (path / 'metadata.yaml').write_text(yaml.safe_dump(doc))


@pytest.mark.parametrize('version', [4, 5, 6, 7, 8, 9])
def test_every_metadata_version_reads(tmp_path, version):
    path = _plain_bag(tmp_path / 'bag')
    _as_version(path, version)
    reader = BagReader(path)
    assert reader.message_counts == {'/points': 4} and reader.cloud_topic() == '/points'
    assert reader.metadata_summary.startswith(f'version {version}')


@pytest.mark.parametrize(
    'edit,words',
    [
        (lambda i: i.update(version=3), ['version 3', 'not supported']),
        (lambda i: i.update(message_count='many'), ['message_count', "'many'"]),
        (
            lambda i: i['topics_with_message_count'][0].update(message_count=1.5),
            ['message_count of /points'],
        ),
        (
            lambda i: i['topics_with_message_count'][0]['topic_metadata'].pop(
                'type_description_hash'
            ),
            ['type_description_hash'],
        ),
        (
            lambda i: i['topics_with_message_count'][0]['topic_metadata'].update(
                offered_qos_profiles='- x'
            ),
            ['offered_qos_profiles', 'not a sequence'],
        ),
    ],
)
def test_malformed_metadata_is_one_error_naming_the_bag(tmp_path, edit, words):
    path = _plain_bag(tmp_path / 'bag')
    doc = yaml.safe_load((path / 'metadata.yaml').read_text())
    edit(doc['rosbag2_bagfile_information'])
    (path / 'metadata.yaml').write_text(yaml.safe_dump(doc))
    with pytest.raises(BagError) as exc:
        BagReader(path)
    assert str(path) in str(exc.value) and all(w in str(exc.value) for w in words)


def test_alias_bomb_in_metadata_is_refused(tmp_path):
    path = _plain_bag(tmp_path / 'bag')
    bomb = 'a: &a [x, x]\n' + ''.join(
        f'b{i}: &b{i} [*{"a" if i == 0 else f"b{i - 1}"}, *{"a" if i == 0 else f"b{i - 1}"}]\n'
        for i in range(80)
    )
    (path / 'metadata.yaml').write_text(bomb)
    with pytest.raises(BagError, match='aliases'):
        BagReader(path)


def test_split_bag_reads_every_file_in_order(tmp_path):
    a, b = _plain_bag(tmp_path / 'a', 3, 10**18), _plain_bag(tmp_path / 'b', 2, 10**18 + 10**9)
    split = tmp_path / 'split'
    split.mkdir()
    shutil.copy(a / 'a_0.mcap', split / 'split_0.mcap')
    shutil.copy(b / 'b_0.mcap', split / 'split_1.mcap')
    doc = yaml.safe_load((a / 'metadata.yaml').read_text())
    info = doc['rosbag2_bagfile_information']
    info['relative_file_paths'] = ['split_0.mcap', 'split_1.mcap']
    info['message_count'] = info['topics_with_message_count'][0]['message_count'] = 5
    (split / 'metadata.yaml').write_text(yaml.safe_dump(doc))
    reader = BagReader(split)
    stamps = [s for s, _ in reader.clouds('/points')]
    assert len(stamps) == 5 and stamps == sorted(stamps) and reader.message_counts['/points'] == 5


def test_fifo_instead_of_mcap_is_refused(tmp_path):
    path = _plain_bag(tmp_path / 'bag')
    os.unlink(path / 'bag_0.mcap')
    os.mkfifo(path / 'bag_0.mcap')
    with pytest.raises(BagError, match='not a regular file'):
        BagReader(path)
    with pytest.raises(BagError, match='not a regular file'):
        BagReader(path / 'bag_0.mcap')


def _cloud_with_fields(names: list[str]):
    field = messages.msg_class('sensor_msgs/msg/PointField')
    fields = [field(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate(names)]
    data = np.zeros(4 * len(names) * 2, dtype=np.uint8)
    return messages.msg_class(POINTCLOUD2)(
        header=messages.header(5, 'world'),
        height=1,
        width=2,
        fields=fields,
        is_bigendian=False,
        point_step=4 * len(names),
        row_step=8 * len(names),
        data=data,
        is_dense=True,
    )


@pytest.mark.parametrize(
    'payload,words',
    [
        (lambda: b'\x00\x01\x00\x00garbage', ['frame 1 on /points', 'not a valid PointCloud2']),
        (
            lambda: messages.serialize(_cloud_with_fields(['x', 'x', 'y', 'z'])),
            ['frame 1 on /points', 'two fields named x'],
        ),
    ],
)
def test_bad_cloud_mid_run_names_bag_and_frame(tmp_path, payload, words):
    path = tmp_path / 'bad'
    with BagWriter(path) as bag:
        bag.write_cloud('/points', 10**18, POINTS)
        bag.write('/points', POINTCLOUD2, 10**18 + 1, payload())
    with pytest.raises(BagError) as exc:
        plan_replay(BagReader(path), ReplayOptions(start_time='0'))
    assert str(path) in str(exc.value) and all(w in str(exc.value) for w in words)


def test_written_bag_looks_like_jazzy(tmp_path):
    from mcap.reader import make_reader

    path = _plain_bag(tmp_path / 'bag', 1)
    info = yaml.safe_load((path / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert (info['version'], info['ros_distro']) == (9, 'jazzy')
    meta = info['topics_with_message_count'][0]['topic_metadata']
    assert meta['offered_qos_profiles'][0]['reliability'] == 'reliable'
    with (path / 'bag_0.mcap').open('rb') as f:
        channel = next(iter(make_reader(f).get_summary().channels.values()))
    assert (
        channel.metadata['topic_type_hash']
        == meta['type_description_hash']
        == messages.type_hash(POINTCLOUD2)
    )


def test_type_hash_is_rihs01_as_jazzy_computes_it():
    # rosbag2 (jazzy)
    # rosbag2_tests/resources/mcap/bag_with_topics_and_service_events/metadata.yaml, recorded
    # 2023-11-07 by Jazzy's rosbag2 when rosbag2_interfaces/msg/WriteSplitEvent held these two
    # fields.
    from rosbags.typesys import get_types_from_msg, get_typestore, Stores

    store = get_typestore(Stores.EMPTY)
    store.register(
        get_types_from_msg(
            'string closed_file\nstring opened_file\n', 'rosbag2_interfaces/msg/WriteSplitEvent'
        )
    )
    assert (
        store.hash_rihs01('rosbag2_interfaces/msg/WriteSplitEvent')
        == 'RIHS01_5ef58f7106a5cff8f5a794028c18117ee21015850ddcc567df449f41932960f8'
    )
    assert messages.TYPESTORE.hash_rihs01 is not None and messages.type_hash(
        POINTCLOUD2
    ).startswith('RIHS01_')


def test_recorder_logs_receive_time_and_keeps_header_stamp(tmp_path):
    from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
    from cloth_bench_ros.nodes.recorder import Recorder
    from cloth_bench_ros.runtime import (
        Header,
        make_qos,
        Node,
        Parameter,
        PointCloud2,
        PointField,
        rclpy,
        SingleThreadedExecutor,
        Time,
    )
    from mcap.reader import make_reader

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    out = tmp_path / 'rec'
    rec = Recorder(
        context=ctx,
        parameter_overrides=[
            Parameter('mode', value='record'),
            Parameter('output', value=str(out)),
            Parameter('record_topics', value=['sim/cloud:sensor_msgs/msg/PointCloud2']),
        ],
    )
    node = Node('pub', namespace='cloth_bench', context=ctx)
    pub = node.create_publisher(PointCloud2, 'sim/cloud', make_qos(10))
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    ex.add_node(node)
    before = time.time_ns()
    pub.publish(
        create_cloud_xyz32(
            Header(stamp=Time(nanoseconds=5).to_msg(), frame_id='world'),
            POINTS,
            PointCloud2,
            PointField,
        )
    )
    ex.spin_until_idle()
    rec.close()
    ctx.shutdown()
    with (out / 'rec_0.mcap').open('rb') as f:
        ((_, _, message),) = list(make_reader(f).iter_messages())
    assert before <= message.log_time <= time.time_ns()
    assert [s for s, _ in BagReader(out).clouds()] == [5]


def test_tf_chain_static_and_interpolated():
    tf = TfBuffer()
    tmsg = messages.msg_class('geometry_msgs/msg/TransformStamped')

    def transform(parent, child, stamp, xyz, quat):
        v = messages.msg_class('geometry_msgs/msg/Vector3')(x=xyz[0], y=xyz[1], z=xyz[2])
        q = messages.msg_class('geometry_msgs/msg/Quaternion')(
            x=quat[0], y=quat[1], z=quat[2], w=quat[3]
        )
        return tmsg(
            header=messages.header(stamp, parent),
            child_frame_id=child,
            transform=messages.msg_class('geometry_msgs/msg/Transform')(translation=v, rotation=q),
        )

    s = np.sqrt(0.5)
    tf.set_transform(
        transform('world', 'base', 0, (1.0, 0.0, 0.0), (0, 0, s, s)), static=True
    )  # yaw 90 deg
    tf.set_transform(transform('base', 'cam', 100, (0.0, 0.0, 0.0), (0, 0, 0, 1)), static=False)
    tf.set_transform(transform('base', 'cam', 300, (0.0, 0.0, 2.0), (0, 0, 0, 1)), static=False)
    m = tf.lookup('world', 'cam', 200)
    assert np.allclose(
        m @ [1.0, 0.0, 0.0, 1.0], [1.0, 1.0, 1.0, 1.0]
    )  # x -> y by the yaw, z halfway to 2
    assert np.allclose(tf.lookup('cam', 'world', 200) @ m, np.eye(4))
    with pytest.raises(TransformError, match='extrapolation'):
        tf.lookup('world', 'cam', 400)
    with pytest.raises(TransformError, match='frame lidar cannot be resolved to world'):
        tf.lookup('world', 'lidar', 200)


def test_start_time_given_or_from_targets():
    assert given_start('1.5', 10**18).bag_ns == 10**18 + 1_500_000_000
    assert given_start('1700000000.25', 10**18).bag_ns == 1_700_000_000_250_000_000
    rest, moved = np.zeros((2, 3)), np.array([[0.0, 0.01, 0.0], [0.0, 0.0, 0.0]])
    start = targets_start([0, 10, 20, 30], [rest, rest, moved, moved], '/targets')
    assert (start.bag_ns, start.precision_s, start.method) == (10, 5e-9, 'targets topic /targets')
    with pytest.raises(AlignmentError, match='never move'):
        targets_start([0, 10], [rest, rest], '/targets')
    with pytest.raises(AlignmentError, match='not a number'):
        given_start('soon', 0)


def test_targets_topic_sets_the_start_of_a_plain_bag(tmp_path):
    path = tmp_path / 'bag'
    pose = messages.msg_class('geometry_msgs/msg/Pose')
    point = messages.msg_class('geometry_msgs/msg/Point')
    with BagWriter(path) as bag:
        for k in range(10):
            stamp = 10**18 + k * 100_000_000
            bag.write_cloud('/points', stamp, POINTS + [0.0, 0.0, 0.5])
            z = 1.0 + (0.1 * (k - 4) if k > 4 else 0.0)
            msg = messages.msg_class(POSE_ARRAY)(
                header=messages.header(stamp),
                poses=[
                    pose(
                        position=point(x=0.0, y=0.0, z=z),
                        orientation=messages.msg_class('geometry_msgs/msg/Quaternion')(
                            x=0.0, y=0.0, z=0.0, w=1.0
                        ),
                    )
                ],
            )
            bag.write_message('/arm/targets', msg, stamp)
    # its 0.9 s motion is not the task's: refused, unless the task's motion is asked for
    with pytest.raises(AlignmentError, match='does not match the task dynamic'):
        plan_replay(BagReader(path), ReplayOptions(targets_topic='/arm/targets', clean='off'))
    plan = plan_replay(
        BagReader(path), ReplayOptions(targets_topic='/arm/targets', clean='off', motion='task')
    )
    assert plan.start.bag_ns == 10**18 + 400_000_000
    assert plan.counts['before_start'] == 4 and plan.counts['to_send'] == 6


def test_cleaning_crops_removes_table_and_outliers_and_counts_them():
    rng = np.random.default_rng(1)
    cloth = np.column_stack(
        [rng.uniform(0, 0.5, 2000), rng.normal(0, 0.002, 2000), rng.uniform(0.4, 1.0, 2000)]
    )
    table = np.column_stack(
        [rng.uniform(-0.2, 0.7, 800), rng.uniform(-0.5, 0.5, 800), np.full(800, 0.195)]
    )
    far = np.array([[5.0, 5.0, 5.0]] * 10)
    stray = np.array([[0.25, 0.3, 0.7], [0.1, -0.3, 0.5]])
    organized = np.concatenate([cloth, table, far, stray, np.full((88, 3), np.nan)]).reshape(
        50, 58, 3
    )
    lo, hi = workspace_box(
        np.array([[0.0, 0.0, 1.0], [0.5, 0.0, 1.0], [0.25, 0.2, 0.5]])
    )  # grippers go down
    stats = CleaningStats()
    out = clean(organized, CleaningConfig(lo, hi, voxel=0.01), stats)
    assert (stats.non_finite, stats.outside_box) == (88, 10)
    assert 790 <= stats.table_plane <= 800 and stats.outliers >= 2
    assert stats.voxel_merged > 0 and stats.points_out == len(out)
    assert (
        sum(
            v for k, v in stats.as_dict().items() if k not in ('frames', 'points_in', 'points_out')
        )
        == stats.points_in - stats.points_out
    )


def test_table_plane_is_kept_where_the_cloth_lies_on_the_table():
    from cloth_bench_ros.data.replay import cleaning_config

    assert cleaning_config(ReplayOptions(primitive='dynamic'), project_bag=False).table_plane
    assert not cleaning_config(
        ReplayOptions(primitive='quasi_static'), project_bag=False
    ).table_plane
    assert cleaning_config(
        ReplayOptions(primitive='quasi_static', table_plane='remove'), False
    ).table_plane
    assert (
        cleaning_config(ReplayOptions(), project_bag=True) is None
    )  # the project's bags are clean already
    with pytest.raises(ValueError, match='table plane mode'):
        cleaning_config(ReplayOptions(table_plane='maybe'), False)
