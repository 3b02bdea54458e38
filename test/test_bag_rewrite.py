"""`cloth-bench bag rewrite` and the layout of the bundled bags, on real MCAP files."""

from __future__ import annotations

from pathlib import Path

from cloth_bench_ros.cli import main
from cloth_bench_ros.data import (
    BagError,
    BagReader,
    BagWriter,
    CLOUD_TOPIC,
    messages,
    TARGETS_TOPIC,
    TrialInfo,
)
from cloth_bench_ros.data.bag_rewrite import rewrite_bag
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
import numpy as np
import pytest
import yaml

BAGS = Path(__file__).resolve().parent.parent / 'bags'
BUNDLED = sorted(p.name for p in BAGS.iterdir() if (p / 'metadata.yaml').exists())


def channels(bag: Path) -> list:
    with next(bag.glob('*.mcap')).open('rb') as f:
        return list(make_reader(f).get_summary().channels.values())


def logged(bag: Path) -> list[tuple[str, str, int, bytes]]:
    return [(t, m, ns, bytes(cdr)) for t, m, ns, cdr in BagReader(bag).logged_messages()]


def test_bundled_bags_are_all_there():
    assert len(BUNDLED) == 8, BUNDLED


@pytest.mark.parametrize('name', BUNDLED)
def test_bundled_bag_layout_is_jazzy(name):
    """metadata.yaml's version and ros_distro agree (9 is Jazzy's), and every channel is hashed."""
    info = yaml.safe_load((BAGS / name / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information'
    ]
    assert (info['version'], info['ros_distro']) == (9, 'jazzy')
    yaml_hashes = {
        t['topic_metadata']['name']: t['topic_metadata']['type_description_hash']
        for t in info['topics_with_message_count']
    }
    chans = channels(BAGS / name)
    assert {c.topic for c in chans} == set(yaml_hashes)
    for c in chans:
        assert c.metadata.get('topic_type_hash', '').startswith('RIHS01_'), (
            name,
            c.topic,
            c.metadata,
        )
        assert (
            c.metadata['topic_type_hash']
            == yaml_hashes[c.topic]
            == messages.type_hash(info_type(info, c.topic))
        )


def info_type(info: dict, topic: str) -> str:
    return next(
        t['topic_metadata']['type']
        for t in info['topics_with_message_count']
        if t['topic_metadata']['name'] == topic
    )


def write_old_layout(src: Path, dst: Path) -> Path:
    """Write src's messages in the older layout: metadata 8/humble, QoS as a string, no hash."""
    dst.mkdir()
    with next(src.glob('*.mcap')).open('rb') as f, (dst / f'{dst.name}_0.mcap').open('wb') as out:
        reader = make_reader(f)
        writer = McapWriter(out, compression=CompressionType.ZSTD)
        writer.start(profile='ros2', library='old writer')
        for rec in reader.iter_metadata():
            writer.add_metadata(rec.name, dict(rec.metadata))
        f.seek(0)
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            if schema.id not in schema_ids:
                schema_ids[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channel_ids:
                meta = {k: v for k, v in channel.metadata.items() if k != 'topic_type_hash'}
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic, 'cdr', schema_ids[schema.id], meta
                )
            writer.add_message(channel_ids[channel.id], msg.log_time, msg.data, msg.publish_time)
        writer.finish()
    doc = yaml.safe_load((src / 'metadata.yaml').read_text())
    info = doc['rosbag2_bagfile_information']
    info.update(version=8, ros_distro='humble', relative_file_paths=[f'{dst.name}_0.mcap'])
    info['files'][0]['path'] = f'{dst.name}_0.mcap'
    for t in info['topics_with_message_count']:
        t['topic_metadata']['offered_qos_profiles'] = yaml.safe_dump(
            t['topic_metadata']['offered_qos_profiles']
        )
    (dst / 'metadata.yaml').write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst


@pytest.fixture
def recorded_bag(tmp_path) -> Path:
    """Return a small bag whose log times are receive times, not stamps, with two data topics."""
    trial = TrialInfo(
        cloth='linen', trial=2, primitive='dynamic', change_of_phase_frame=90, source='test'
    )
    rng = np.random.default_rng(3)
    with BagWriter(tmp_path / 'rec', trial, chunk_size=4096) as w:
        for k in range(6):
            stamp = k * 33_333_333
            w.write_cloud(CLOUD_TOPIC, stamp, rng.uniform(-1, 1, (50, 3)))
            pose = messages.msg_class('geometry_msgs/msg/PoseArray')(
                header=messages.header(stamp), poses=[]
            )
            w.write(
                TARGETS_TOPIC,
                pose.__msgtype__,
                stamp,
                messages.serialize(pose),
                log_time_ns=stamp + 5_000_000 + k,
            )
    return write_old_layout(tmp_path / 'rec', tmp_path / 'old')


def test_rewrite_keeps_messages_and_trial_and_adds_the_jazzy_layout(recorded_bag, tmp_path):
    old = BagReader(recorded_bag)
    assert old.metadata_summary == 'version 8, ros_distro humble'
    assert all('topic_type_hash' not in c.metadata for c in channels(recorded_bag))
    counts = rewrite_bag(recorded_bag, tmp_path / 'new')
    new = BagReader(tmp_path / 'new')
    assert counts == {'/cloth_bench/real/trial': 1, CLOUD_TOPIC: 6, TARGETS_TOPIC: 6}
    assert new.metadata_summary == 'version 9, ros_distro jazzy'
    assert logged(tmp_path / 'new') == logged(recorded_bag)
    assert any(
        ns % 1000 != 0 for _, _, ns, _ in logged(tmp_path / 'new')
    )  # receive times kept, not stamps
    assert [s for _, _, s, _ in new.raw_messages()] == [s for _, _, s, _ in old.raw_messages()]
    assert new.trial == old.trial and new.custom_data == old.custom_data
    assert all(
        c.metadata['topic_type_hash'].startswith('RIHS01_') for c in channels(tmp_path / 'new')
    )


def test_rewrite_refuses_custom_data_it_would_drop(recorded_bag, tmp_path):
    meta = recorded_bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['custom_data']['someone.else'] = 'x'
    meta.write_text(yaml.safe_dump(doc))
    with pytest.raises(BagError, match='custom_data'):
        rewrite_bag(recorded_bag, tmp_path / 'new')
    assert not (tmp_path / 'new').exists()


def test_cli_bag_rewrite(recorded_bag, tmp_path, capsys):
    assert main(['bag', 'rewrite', str(recorded_bag), str(tmp_path / 'new')]) == 0
    assert 'unchanged' in capsys.readouterr().out
    assert main(['bag', 'rewrite', str(recorded_bag), str(recorded_bag)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith('cloth-bench: error:') and str(recorded_bag) in err and '\n' not in err
    assert (
        main(['bag', 'rewrite', str(recorded_bag), str(tmp_path / 'new')]) == 2
    )  # exists, not empty
    assert 'already exists' in capsys.readouterr().err
    assert logged(recorded_bag) == logged(tmp_path / 'new')
