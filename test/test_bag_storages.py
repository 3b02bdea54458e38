"""
Every rosbag2 storage a user records, written by independent writers, scores like the original.

The variants of a bundled bag are made by rosbags' Writer (sqlite3 and MCAP storage, file and
message compression, metadata versions 8 and 9, older versions by editing metadata.yaml as
earlier rosbag2 releases wrote it), by the mcap library's own writer (a bare .mcap), split into
two storage files, and with metadata.yaml removed (a recording killed before it was written).
Each is lossless, so each must give the same CD/HD digits and frame counts as the original.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import shutil
import subprocess
import tempfile

from cloth_bench_ros import cli
from cloth_bench_ros.data import BagError, BagReader
from cloth_bench_ros.data.bag_storage import decompressed_dirs, DECOMPRESSED_PREFIX
from cloth_bench_ros.paths import bundled_bag
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import get_typestore, Stores
import yaml

SOURCE = bundled_bag('towel', 'dynamic')
RUN = ['--grid', '6x8', '--rate', '100']
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def write_with_rosbags(
    out: Path,
    storage: str,
    compression: str | None = None,
    version: int = 9,
    messages: list | None = None,
) -> Path:
    """Return the source bag's messages written by rosbags' Writer, custom_data included."""
    reader = BagReader(SOURCE)
    plugin = StoragePlugin.SQLITE3 if storage == 'sqlite3' else StoragePlugin.MCAP
    writer = Writer(out, version=version, storage_plugin=plugin)
    if compression:
        mode = CompressionMode.FILE if compression == 'file' else CompressionMode.MESSAGE
        writer.set_compression(mode, CompressionFormat.ZSTD)
    for key, value in reader.custom_data.items():
        writer.set_custom_data(key, value)
    with writer:
        connections = {}
        for topic, msgtype, log_ns, cdr in (
            messages if messages is not None else reader.logged_messages()
        ):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            writer.write(connections[topic], log_ns, cdr)
    return out


def downgrade_metadata(bag: Path, version: int) -> None:
    """metadata.yaml of a version-8 bag rewritten as rosbag2 `version` (4-7) wrote it."""
    path = bag / 'metadata.yaml'
    doc = yaml.safe_load(path.read_text())
    info = doc['rosbag2_bagfile_information']
    info['version'] = version
    info.pop('ros_distro', None)  # 8
    if version < 7:
        for topic in info['topics_with_message_count']:
            topic['topic_metadata'].pop('type_description_hash', None)
    if version < 6:
        info.pop('custom_data', None)
    if version < 5:
        info.pop('files', None)
    path.write_text(yaml.safe_dump(doc))


# The sqlite3 schema each metadata version's rosbag2 wrote: 2 (Foxy: no schema table), 3 (Humble:
# schema and metadata tables), 4 (Iron on: message definitions, type description hashes).
DATABASE_SCHEMA = {4: 2, 5: 3, 6: 3, 7: 4, 8: 4, 9: 4}


def downgrade_database(database: Path, schema: int) -> None:
    """Rewrite a schema-4 .db3 in an older rosbag2 sqlite3 schema."""
    import sqlite3

    with sqlite3.connect(database) as db:
        if schema < 4:
            db.execute('DROP TABLE message_definitions')
            db.execute('ALTER TABLE topics DROP COLUMN type_description_hash')
            db.execute('UPDATE schema SET schema_version = ?', (schema,))
        if schema < 3:
            db.execute('DROP TABLE schema')
            db.execute('DROP TABLE metadata')
        tables = {
            row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
        }
    db.close()
    assert ('message_definitions' in tables) == (schema >= 4) and ('schema' in tables) == (
        schema >= 3
    )


def write_split(out: Path, storage: str, parts: int = 2) -> Path:
    """
    Return the source's messages in `parts` storage files of one bag.

    Named and listed as `ros2 bag record --max-bag-size` splits them (`<bag>_0`, `<bag>_1`, ...).
    """
    messages = list(BagReader(SOURCE).logged_messages())
    suffix = '.db3' if storage == 'sqlite3' else '.mcap'
    bounds = [round(i * len(messages) / parts) for i in range(parts + 1)]
    info: dict = {}
    for i in range(parts):
        part = write_with_rosbags(
            out.parent / f'{out.name}_part{i}',
            storage,
            messages=messages[bounds[i]:bounds[i + 1]],
        )
        name = f'{out.name}_{i}{suffix}'
        out.mkdir(exist_ok=True)
        (part / f'{part.name}{suffix}').rename(out / name)
        part_info = yaml.safe_load((part / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information'
        ]
        part_info['files'][0]['path'] = name
        if not info:
            info = {**part_info, 'relative_file_paths': [name]}
            continue
        info['relative_file_paths'].append(name)
        info['files'].append(part_info['files'][0])
        info['message_count'] += part_info['message_count']
        counts = {
            t['topic_metadata']['name']: t['message_count']
            for t in part_info['topics_with_message_count']
        }
        known = {t['topic_metadata']['name'] for t in info['topics_with_message_count']}
        for topic in info['topics_with_message_count']:
            topic['message_count'] += counts.get(topic['topic_metadata']['name'], 0)
        info['topics_with_message_count'] += [
            t
            for t in part_info['topics_with_message_count']
            if t['topic_metadata']['name'] not in known
        ]
    (out / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': info}))
    return out


def write_bare_mcap(out: Path) -> Path:
    """Return a single .mcap written by the mcap library's own writer (lz4 chunks)."""
    from cloth_bench_ros.data.messages import msgdef
    from mcap.writer import CompressionType
    from mcap.writer import Writer as McapWriter

    out.mkdir()
    path = out / 'recording.mcap'
    with path.open('wb') as f:
        writer = McapWriter(f, compression=CompressionType.LZ4)
        writer.start(profile='ros2', library='test')
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for topic, msgtype, log_ns, cdr in BagReader(SOURCE).logged_messages():
            if msgtype not in schemas:
                schemas[msgtype] = writer.register_schema(
                    msgtype, 'ros2msg', msgdef(msgtype).encode()
                )
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, 'cdr', schemas[msgtype])
            writer.add_message(
                channels[topic], log_time=log_ns, data=bytes(cdr), publish_time=log_ns
            )
        writer.finish()
    return path


VARIANTS = {
    "sqlite3 (Humble's default)": lambda out: write_with_rosbags(out, 'sqlite3'),
    'sqlite3, metadata version 8': lambda out: write_with_rosbags(out, 'sqlite3', version=8),
    'mcap, file compression zstd': lambda out: write_with_rosbags(out, 'mcap', 'file'),
    'mcap, message compression zstd': lambda out: write_with_rosbags(out, 'mcap', 'message'),
    'sqlite3, file compression zstd': lambda out: write_with_rosbags(out, 'sqlite3', 'file'),
    'sqlite3, message compression zstd': lambda out: write_with_rosbags(out, 'sqlite3', 'message'),
    'sqlite3 split in two files': lambda out: write_split(out, 'sqlite3'),
    'mcap split in three files': lambda out: write_split(out, 'mcap', 3),
}


@pytest.fixture(scope='module')
def original(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp('original') / 'run'
    assert cli.main(['run', '--bag', str(SOURCE), '--output', str(out), *RUN]) == 0
    return json.loads((out / 'summary.json').read_text())


def scores(summary: dict) -> tuple:
    m = summary['engines']['mujoco']
    return (
        m['CD_d'],
        m['HD_d'],
        m['frames_scored'],
        m['frames_in_window'],
        summary['real']['accounting'],
        summary['real']['change_of_phase'],
    )


def _score(bag: Path, tmp_path: Path) -> dict:
    out = tmp_path / 'run'
    assert cli.main(['run', '--bag', str(bag), '--output', str(out), *RUN]) == 0
    return json.loads((out / 'summary.json').read_text())


@pytest.mark.slow
@pytest.mark.parametrize('variant', list(VARIANTS))
def test_a_lossless_variant_scores_exactly_like_the_original(variant, original, tmp_path):
    bag = VARIANTS[variant](tmp_path / 'variant')
    reader = BagReader(bag)
    assert (
        reader.trial == BagReader(SOURCE).trial
        and reader.message_counts == BagReader(SOURCE).message_counts
    )
    assert scores(_score(bag, tmp_path)) == scores(original)


@pytest.mark.parametrize('version', [4, 5, 6, 7])
def test_older_metadata_versions_read(version, tmp_path):
    bag = write_with_rosbags(tmp_path / 'old', 'sqlite3', version=8)
    downgrade_metadata(bag, version)
    downgrade_database(next(bag.glob('*.db3')), DATABASE_SCHEMA[version])
    reader = BagReader(bag)
    assert reader.metadata_summary.startswith(f'version {version}')
    original = [(s, p.tobytes()) for s, p in BagReader(SOURCE).clouds()]
    assert [(s, p.tobytes()) for s, p in reader.clouds()] == original
    assert (
        reader.trial == BagReader(SOURCE).trial
    )  # from the trial topic when custom_data is older than v6


@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_killed_recording_without_metadata_reads_its_files(storage, original, tmp_path):
    bag = write_with_rosbags(tmp_path / 'killed', storage)
    (bag / 'metadata.yaml').unlink()
    with pytest.warns(UserWarning, match='has no metadata.yaml'):
        reader = BagReader(bag)
    assert reader.message_counts == BagReader(SOURCE).message_counts
    assert scores(_score(bag, tmp_path)) == scores(original)


@pytest.mark.slow
@pytest.mark.parametrize('storage', ['sqlite3', 'mcap'])
def test_a_killed_split_recording_is_read_in_file_number_order(storage, original, tmp_path):
    bag = write_split(tmp_path / 'killed', storage, parts=12)
    (bag / 'metadata.yaml').unlink()
    with pytest.warns(UserWarning, match='has no metadata.yaml'):
        reader = BagReader(bag)
    suffix = '.db3' if storage == 'sqlite3' else '.mcap'
    assert [f.name for f in reader.files] == [
        f'killed_{i}{suffix}' for i in range(12)
    ]  # _10 after _9
    assert [s for s, _ in reader.clouds()] == [s for s, _ in BagReader(SOURCE).clouds()]
    assert scores(_score(bag, tmp_path)) == scores(original)


def test_a_killed_file_compressed_recording_says_what_to_do(tmp_path, capsys):
    # --compression-mode file compresses each file when it is closed: a killed recording leaves
    # the earlier files compressed, the last one not, and no metadata.yaml.
    bag = write_split(tmp_path / 'killed', 'mcap', parts=2)
    (bag / 'metadata.yaml').unlink()
    compressed = write_with_rosbags(tmp_path / 'compressed', 'mcap', 'file')
    (bag / 'killed_0.mcap').unlink()
    next(compressed.glob('*.mcap.zstd')).rename(bag / 'killed_0.mcap.zstd')
    with pytest.raises(
        BagError, match=r'compressed storage files \(killed_0.mcap.zstd\).*zstd -d --rm'
    ):
        BagReader(bag)
    assert cli.main(['run', '--bag', str(bag), '--output', str(tmp_path / 'o'), *RUN]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.parametrize('compression', ['file', 'message'])
def test_a_damaged_compressed_bag_is_one_line(compression, tmp_path, capsys):
    bag = write_with_rosbags(
        tmp_path / 'torn', 'sqlite3' if compression == 'message' else 'mcap', compression
    )
    storage = next(f for f in bag.iterdir() if f.name != 'metadata.yaml')
    data = storage.read_bytes()
    storage.write_bytes(data[: len(data) // 2])
    assert cli.main(['run', '--bag', str(bag), '--output', str(tmp_path / 'o'), *RUN]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bag) in err and 'internal error' not in err


@pytest.mark.slow
def test_a_bare_mcap_from_the_mcap_writer_scores_like_the_original(original, tmp_path):
    path = write_bare_mcap(tmp_path / 'bare')
    assert scores(_score(path, tmp_path)) == scores(original)


@pytest.mark.parametrize('compression', ['file', 'message'])
def test_a_storage_file_of_a_compressed_bag_reads_as_its_bag(compression, tmp_path):
    # Only metadata.yaml says a file is compressed, or that its messages are.
    bag = write_with_rosbags(tmp_path / compression, 'mcap', compression)
    reader = BagReader(next(f for f in bag.iterdir() if f.name != 'metadata.yaml'))
    assert reader.path == bag and reader.storage == f'mcap, compression {compression}:zstd'
    assert [(s, p.tobytes()) for s, p in reader.clouds()] == [
        (s, p.tobytes()) for s, p in BagReader(SOURCE).clouds()
    ]


def test_bag_info_names_the_storage(tmp_path, capsys):
    bag = write_with_rosbags(tmp_path / 'humble', 'sqlite3', 'file')
    assert cli.main(['bag', 'info', str(bag)]) == 0
    assert 'storage:      sqlite3, compression file:zstd' in capsys.readouterr().out


def test_an_unreadable_database_is_one_line(tmp_path, capsys):
    bag = write_with_rosbags(tmp_path / 'broken', 'sqlite3')
    database = next(bag.glob('*.db3'))
    database.write_bytes(b'not a database' * 100)
    with pytest.raises(BagError, match=f'bag {bag}'):
        BagReader(bag)
    assert cli.main(['run', '--bag', str(bag), '--output', str(tmp_path / 'o'), *RUN]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bag) in err


def test_a_file_compressed_bag_is_decompressed_once_per_reader(tmp_path, monkeypatch):
    from rosbags.rosbag2 import Reader

    bag = write_with_rosbags(tmp_path / 'file', 'mcap', 'file')
    opened = []
    real_open = Reader.open
    monkeypatch.setattr(Reader, 'open', lambda self: (opened.append(self), real_open(self))[1])
    reader = BagReader(bag)
    assert reader.trial is not None
    passes = [[s for s, _ in reader.clouds()] for _ in range(3)]
    assert len(opened) == 1 and passes[0] == passes[2] == [
        s for s, _ in BagReader(SOURCE).clouds()
    ]
    reader.close()
    assert [s for s, _ in reader.clouds()] == passes[0] and len(
        opened
    ) == 2  # reopened after close


def _open_fds() -> dict[int, str]:
    """Return this process's open file descriptors and what each points to."""
    out = {}
    for fd in Path('/proc/self/fd').iterdir():
        try:
            out[int(fd.name)] = os.readlink(fd)
        except OSError:  # the descriptor of the listing itself, closed already
            continue
    return out


@pytest.mark.slow
@pytest.mark.parametrize(
    'storage, compression', [('sqlite3', None), ('sqlite3', 'file'), ('mcap', 'file')]
)
def test_a_run_leaves_no_file_open_and_no_decompressed_copy(
    storage, compression, original, tmp_path
):
    # `original` ran once already: what a first run opens for good (imports, engines) is open.
    bag = write_with_rosbags(tmp_path / 'bag', storage, compression)
    before, copies = _open_fds(), set(decompressed_dirs(os.getpid()))  # other tests' readers
    _score(bag, tmp_path)
    left = {fd: target for fd, target in _open_fds().items() if fd not in before}
    assert not left, f'file descriptors left open by the run: {left}'
    assert set(decompressed_dirs(os.getpid())) <= copies, 'a decompressed copy stayed on disk'


def test_a_decompressed_copy_left_by_a_killed_process_is_removed_on_the_next_open(tmp_path):
    dead = subprocess.Popen(['true'])  # its pid is free once it has been waited for
    dead.wait()
    orphan = Path(tempfile.mkdtemp(prefix=f'{DECOMPRESSED_PREFIX}{dead.pid}-'))
    (orphan / 'copy.db3').write_bytes(b'decompressed')
    mine = Path(tempfile.mkdtemp(prefix=f'{DECOMPRESSED_PREFIX}{os.getpid()}-'))
    try:
        bag = write_with_rosbags(tmp_path / 'file', 'sqlite3', 'file')
        copies = set(decompressed_dirs(os.getpid()))
        with BagReader(bag) as reader:
            assert reader.trial is not None
            assert len(set(decompressed_dirs(os.getpid())) - copies) == 1  # the reader's own
        assert set(decompressed_dirs(os.getpid())) == copies  # removed at close
        assert not orphan.exists() and mine.exists()  # a live process's copy stays
    finally:
        shutil.rmtree(orphan, ignore_errors=True)
        shutil.rmtree(mine, ignore_errors=True)
