"""The bag layer on real MCAP files written by the tests (no mocks)."""

from __future__ import annotations

import os
from pathlib import Path
import shutil
import signal
import warnings

from cloth_bench_ros.data import (
    BagError,
    BagReader,
    BagWarning,
    BagWriter,
    CLOUD_TOPIC,
    describe,
    messages,
    TARGETS_TOPIC,
    trial_from_message,
    TRIAL_TOPIC,
    TrialInfo,
)
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

NS = 1_000_000_000


def stamp(k: int, fps: float = 30.0) -> int:
    return round(k * NS / fps)


def make_trial(**kw) -> TrialInfo:
    base = {
        'cloth': 'towel',
        'trial': 1,
        'primitive': 'dynamic',
        'change_of_phase_frame': 98,
        'source': 'test',
    }
    base.update(kw)
    return TrialInfo(**base)


def frames(n: int, points: int = 500, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, (points, 3)) for _ in range(n)]


def write_bag(path: Path, clouds: list[np.ndarray], trial: TrialInfo | None = None, **kw) -> Path:
    with BagWriter(path, trial, **kw) as w:
        for k, pts in enumerate(clouds):
            w.write_cloud(CLOUD_TOPIC, stamp(k), pts)
    return path


def one_line(exc: pytest.ExceptionInfo, name: str) -> str:
    text = str(exc.value)
    assert '\n' not in text
    assert name in text, text
    return text


def test_round_trip(tmp_path: Path) -> None:
    clouds = frames(12)
    trial = make_trial(transform=np.diag([1.0, 2.0, 3.0, 1.0]).tolist(), fps=30.0)
    bag = tmp_path / 'trial'
    with BagWriter(bag, trial) as w:
        pose_array = messages.msg_class(messages.POSE_ARRAY)(
            header=messages.header(stamp(0)), poses=[]
        )
        assert w.write_message(TARGETS_TOPIC, pose_array, stamp(0))
        for k, pts in enumerate(clouds):
            assert w.write_cloud(CLOUD_TOPIC, stamp(k), pts)
    assert w.counts == {TRIAL_TOPIC: 1, TARGETS_TOPIC: 1, CLOUD_TOPIC: 12}
    assert w.written == 14
    assert sorted(p.name for p in bag.iterdir()) == ['metadata.yaml', 'trial_0.mcap']

    r = BagReader(bag)
    assert r.complete and not r.warnings
    assert r.topics == {
        TRIAL_TOPIC: messages.DIAGNOSTIC_ARRAY,
        TARGETS_TOPIC: messages.POSE_ARRAY,
        CLOUD_TOPIC: messages.POINTCLOUD2,
    }
    assert r.message_counts[CLOUD_TOPIC] == 12
    assert r.trial == trial
    assert r.compression == 'zstd'
    assert r.cloud_topic() == CLOUD_TOPIC
    got = list(r.clouds())
    assert [s for s, _ in got] == [stamp(k) for k in range(12)]
    for (_, pts), ref in zip(got, clouds):
        assert pts.dtype == np.float64 and pts.shape == ref.shape
        np.testing.assert_array_equal(pts, ref.astype(np.float32).astype(np.float64))
    assert r.stats.frames == 12 and r.stats.irregular_intervals == 0
    # The trial also travels in-band, first, on TRIAL_TOPIC.
    topic, _, msg = next(iter(r.messages()))
    assert topic == TRIAL_TOPIC and trial_from_message(msg) == trial


def test_trial_fallbacks(tmp_path: Path) -> None:
    trial = make_trial(change_of_phase_frame=None, primitive='quasi_static')
    bag = write_bag(tmp_path / 'b', frames(2), trial)
    # Without metadata.yaml the MCAP metadata record still carries the trial.
    (bag / 'metadata.yaml').unlink()
    with pytest.warns(BagWarning, match='no metadata.yaml'):
        assert BagReader(bag).trial == trial
    assert BagReader(bag / 'b_0.mcap').trial == trial
    assert BagReader(write_bag(tmp_path / 'none', frames(1))).trial is None


def test_trial_info_dict_round_trip() -> None:
    trial = make_trial(transform=(np.eye(4) * 2).tolist())
    assert TrialInfo.from_dict(trial.to_dict()) == trial
    assert TrialInfo.from_strings(trial.to_strings()) == trial
    with pytest.raises(ValueError, match='4x4'):
        make_trial(transform=np.eye(3).tolist())


def test_rosbags_and_mcap_readers_decode_the_same_points(tmp_path: Path) -> None:
    clouds = frames(5, points=300, seed=3)
    bag = write_bag(tmp_path / 'both', clouds, make_trial())
    ours = [pts for _, pts in BagReader(bag).clouds()]

    from cloth_bench_ros.core.pointcloud2 import read_xyz

    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == CLOUD_TOPIC]
        assert conns[0].msgtype == messages.POINTCLOUD2
        via_rosbags = [
            (ts, read_xyz(reader.deserialize(raw, c.msgtype)))
            for c, ts, raw in reader.messages(conns)
        ]
    with (bag / 'both_0.mcap').open('rb') as f:
        mreader = make_reader(f, decoder_factories=[DecoderFactory()])
        via_mcap = []
        for schema, channel, message, decoded in mreader.iter_decoded_messages(
            topics=[CLOUD_TOPIC]
        ):
            assert schema.encoding == 'ros2msg' and channel.message_encoding == 'cdr'
            via_mcap.append((message.log_time, read_xyz(decoded)))
        assert {c.compression for c in mreader.get_summary().chunk_indexes} == {'zstd'}
    assert [t for t, _ in via_rosbags] == [t for t, _ in via_mcap] == [stamp(k) for k in range(5)]
    for a, (_, b), (_, c) in zip(ours, via_rosbags, via_mcap):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, c)


def test_missing_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError) as exc:
        BagReader(tmp_path / 'nope')
    assert 'does not exist' in one_line(exc, 'nope')


def test_directory_that_is_not_a_bag(tmp_path: Path) -> None:
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError) as exc:
        BagReader(tmp_path / 'empty')
    assert 'not a rosbag2 bag' in one_line(exc, 'empty')


def test_random_bytes(tmp_path: Path) -> None:
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(np.random.default_rng(1).bytes(4096))
    with pytest.raises(BagError) as exc:
        BagReader(junk)
    assert 'not an MCAP file' in one_line(exc, 'junk.mcap')


def test_corrupt_metadata_yaml(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'meta', frames(2))
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed\n')
    with pytest.raises(BagError) as exc:
        BagReader(bag)
    one_line(exc, 'metadata.yaml')
    (bag / 'metadata.yaml').write_text('something: else\n')
    with pytest.raises(BagError) as exc:
        BagReader(bag)
    assert 'missing key' in one_line(exc, 'metadata.yaml')


def test_corrupt_chunk(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'corrupt', frames(20, points=2000), chunk_size=64 * 1024)
    mcap = bag / 'corrupt_0.mcap'
    data = bytearray(mcap.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(64)  # zero out part of a compressed chunk
    mcap.write_bytes(bytes(data))
    reader = BagReader(bag)  # the summary is intact
    with pytest.raises(BagError) as exc:
        list(reader.clouds())
    assert 'corrupt' in one_line(exc, 'corrupt_0.mcap')


def test_truncated_to_nothing(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'cut', frames(2))
    mcap = bag / 'cut_0.mcap'
    mcap.write_bytes(mcap.read_bytes()[:5])
    with pytest.raises(BagError) as exc:
        BagReader(bag)
    one_line(exc, 'cut_0.mcap')


@pytest.mark.parametrize('keep_metadata', [True, False])
def test_truncated_without_summary_reads_up_to_the_damage(
    tmp_path: Path, keep_metadata: bool
) -> None:
    clouds = frames(30, points=2000, seed=5)
    bag = write_bag(tmp_path / 'rec', clouds, make_trial(), chunk_size=32 * 1024)
    mcap = bag / 'rec_0.mcap'
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(len(data) * 0.6)])  # summary and the last chunks are gone
    if not keep_metadata:
        (bag / 'metadata.yaml').unlink()  # a recorder killed before close
    with pytest.warns(BagWarning, match='truncated'):
        reader = BagReader(bag)
    assert not reader.complete
    assert any('truncated' in w and 'rec_0.mcap' in w for w in reader.warnings)
    assert reader.trial == make_trial()
    got = list(reader.clouds())
    assert 5 < len(got) < 30
    for k, (t, pts) in enumerate(got):
        assert t == stamp(k)
        np.testing.assert_array_equal(pts, clouds[k].astype(np.float32))
    assert 'complete:     no' in describe(bag)


def test_no_pointcloud2_topic(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'targets') as w:
        msg = messages.msg_class(messages.POSE_ARRAY)(header=messages.header(0), poses=[])
        w.write_message(TARGETS_TOPIC, msg, 0)
    reader = BagReader(tmp_path / 'targets')
    with pytest.raises(BagError) as exc:
        reader.cloud_topic()
    assert 'has no sensor_msgs/msg/PointCloud2 topic' in one_line(exc, 'targets')
    with pytest.raises(BagError):
        list(reader.clouds())


def test_cloud_topic_choice(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'two') as w:
        w.write_cloud('/a/cloud', 0, np.zeros((1, 3)))
        w.write_cloud('/b/cloud', 0, np.zeros((1, 3)))
    reader = BagReader(tmp_path / 'two')
    with pytest.raises(BagError, match='several'):
        reader.cloud_topic()
    assert reader.cloud_topic('/b/cloud') == '/b/cloud'
    assert len(list(reader.clouds('/a/cloud'))) == 1
    with pytest.raises(BagError, match='no topic /c'):
        list(reader.clouds('/c'))


def test_nan_points_and_empty_clouds_are_counted(tmp_path: Path) -> None:
    clouds = frames(6, points=100)
    clouds[1][[3, 7, 50]] = np.nan
    clouds[2][0, 2] = np.inf
    clouds[3] = np.zeros((0, 3))
    clouds[4] = np.full((10, 3), np.nan)
    reader = BagReader(write_bag(tmp_path / 'nan', clouds))
    got = list(reader.clouds())
    assert [t for t, _ in got] == [stamp(k) for k in (0, 1, 2, 5)]
    assert [len(p) for _, p in got] == [100, 97, 99, 100]
    assert np.isfinite(np.concatenate([p for _, p in got])).all()
    s = reader.stats
    assert (s.frames, s.messages, s.nan_points_dropped, s.empty_clouds_skipped) == (4, 6, 14, 2)
    assert s.irregular_intervals == 0  # stamps of skipped clouds still count for spacing


def test_cloud_without_xyz(tmp_path: Path) -> None:
    field = messages.msg_class('sensor_msgs/msg/PointField')
    cloud = messages.msg_class(messages.POINTCLOUD2)(
        header=messages.header(0),
        height=1,
        width=2,
        fields=[field(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate('abc')],
        is_bigendian=False,
        point_step=12,
        row_step=24,
        data=np.zeros(24, dtype=np.uint8),
        is_dense=True,
    )
    with BagWriter(tmp_path / 'abc') as w:
        w.write_message(CLOUD_TOPIC, cloud, 0)
    with pytest.raises(BagError) as exc:
        list(BagReader(tmp_path / 'abc').clouds())
    assert 'no x/y/z field' in one_line(exc, 'abc')


def test_irregular_intervals(tmp_path: Path) -> None:
    bag = tmp_path / 'gaps'
    at15 = stamp(6) + round(NS / 15)
    stamps = [stamp(k) for k in (0, 1, 2, 4, 5, 6)] + [at15, at15 + stamp(1) + 2_000_000]
    with BagWriter(bag, make_trial()) as w:
        for t in stamps:
            w.write_cloud(CLOUD_TOPIC, t, np.ones((4, 3)))
    reader = BagReader(bag)
    assert len(list(reader.clouds())) == 8
    # the dropped frame 3 and the 15 Hz step are irregular; 2 ms of jitter is not
    assert reader.stats.irregular_intervals == 2
    with BagWriter(tmp_path / 'at10', make_trial(fps=10.0)) as w:
        for k in range(5):
            w.write_cloud(CLOUD_TOPIC, stamp(k, 10.0), np.ones((4, 3)))
    reader = BagReader(tmp_path / 'at10')
    list(reader.clouds())
    assert reader.stats.irregular_intervals == 0  # spacing is judged against the trial's fps


def test_writer_refuses_bad_input(tmp_path: Path) -> None:
    write_bag(tmp_path / 'exists', frames(1))
    with pytest.raises(BagError, match='already exists'):
        BagWriter(tmp_path / 'exists')
    BagWriter(tmp_path / 'exists', overwrite=True).close()
    with pytest.raises(BagError, match='compression'):
        BagWriter(tmp_path / 'c', compression='gzip')
    with BagWriter(tmp_path / 'types') as w:
        with pytest.raises(BagError, match='unknown message type'):
            w.write('/x', 'nope_msgs/msg/Nope', 0, b'')
        w.write_cloud('/x', 0, np.zeros((1, 3)))
        with pytest.raises(BagError, match='is sensor_msgs/msg/PointCloud2'):
            w.write('/x', messages.POSE_ARRAY, 0, b'')
        with pytest.raises(BagError, match='negative stamp'):
            w.write_cloud('/x', -1, np.zeros((1, 3)))


def test_close_is_idempotent_and_late_writes_are_counted(tmp_path: Path) -> None:
    w = BagWriter(tmp_path / 'idem', compression='none')
    w.write_cloud(CLOUD_TOPIC, 0, np.zeros((3, 3)))
    assert w.close() == {CLOUD_TOPIC: 1}
    assert w.close() == {CLOUD_TOPIC: 1}
    assert w.write_cloud(CLOUD_TOPIC, 1, np.zeros((3, 3))) is False
    assert (w.written, w.rejected) == (1, 1)
    assert BagReader(tmp_path / 'idem').compression == 'none'


class _ClosesWhileSerialising(bytes):
    """CDR bytes whose conversion runs close() mid-write, as a signal handler would."""

    writer: BagWriter

    def __bytes__(self) -> bytes:
        self.writer.close()
        return bytes(memoryview(self))


def test_close_during_write_finishes_that_write_first(tmp_path: Path) -> None:
    w = BagWriter(tmp_path / 'mid')
    w.write_cloud(CLOUD_TOPIC, 0, np.zeros((3, 3)))
    pts = np.ones((3, 3))
    from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32

    msg = create_cloud_xyz32(
        messages.header(stamp(1)),
        pts,
        messages.msg_class(messages.POINTCLOUD2),
        messages.msg_class('sensor_msgs/msg/PointField'),
    )
    cdr = _ClosesWhileSerialising(messages.serialize(msg))
    cdr.writer = w
    assert w.write(CLOUD_TOPIC, messages.POINTCLOUD2, stamp(1), cdr) is True
    assert w.closed and w.written == 2
    got = list(BagReader(tmp_path / 'mid').clouds())
    assert len(got) == 2
    np.testing.assert_array_equal(got[1][1], pts)


def test_signal_handler_close_loses_nothing_acknowledged(tmp_path: Path) -> None:
    w = BagWriter(tmp_path / 'sig', chunk_size=16 * 1024)
    old = signal.signal(signal.SIGUSR1, lambda *_: w.close())
    try:
        cloud = np.random.default_rng(2).random((200, 3))
        for k in range(200):
            if k == 57:
                os.kill(os.getpid(), signal.SIGUSR1)
            w.write_cloud(CLOUD_TOPIC, stamp(k), cloud)
    finally:
        signal.signal(signal.SIGUSR1, old)
    assert w.closed and 57 <= w.written < 200 and w.written + w.rejected == 200
    reader = BagReader(tmp_path / 'sig')
    assert reader.complete and len(list(reader.clouds())) == w.written


def test_describe(tmp_path: Path) -> None:
    clouds = frames(3, points=10)
    clouds[1][0] = np.nan
    text = describe(write_bag(tmp_path / 'info', clouds, make_trial()))
    assert '/cloth_bench/real/cloud  sensor_msgs/msg/PointCloud2  (3 msgs)' in text
    assert 'towel trial 1 dynamic, change of phase 98' in text
    assert '3 frames' in text and '1 NaN points dropped' in text
    assert 'chunk compression zstd' in text


def test_serialize_round_trip() -> None:
    msg = messages.header(stamp(7), 'world')
    back = messages.deserialize(messages.serialize(msg), messages.HEADER)
    assert messages.stamp_ns(back.stamp) == stamp(7) and back.frame_id == 'world'
    with pytest.raises(messages.MessageTypeError):
        messages.deserialize(b'', 'nope_msgs/msg/Nope')


def test_raw_messages_use_header_stamps(tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'raw') as w:
        w.write(
            CLOUD_TOPIC,
            messages.POINTCLOUD2,
            5,
            messages.serialize(
                messages.msg_class(messages.POINTCLOUD2)(
                    header=messages.header(stamp(3)),
                    height=1,
                    width=0,
                    fields=[],
                    is_bigendian=False,
                    point_step=12,
                    row_step=0,
                    data=np.zeros(0, np.uint8),
                    is_dense=True,
                )
            ),
        )
        w.write(
            '/clock',
            'rosgraph_msgs/msg/Clock',
            9,
            messages.serialize(
                messages.msg_class('rosgraph_msgs/msg/Clock')(clock=messages.time_msg(1))
            ),
        )
    got = [(t, s) for t, _, s, _ in BagReader(tmp_path / 'raw').raw_messages()]
    assert got == [(CLOUD_TOPIC, stamp(3)), ('/clock', 9)]


def test_bare_mcap_copy(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / 'bare', frames(3), make_trial())
    copy = tmp_path / 'copy.mcap'
    shutil.copy(bag / 'bare_0.mcap', copy)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        reader = BagReader(copy)
    assert reader.trial == make_trial() and len(list(reader.clouds())) == 3
