"""
The one bag reader of the project: any rosbag2 bag a user records, in record order.

A bag is a directory holding `metadata.yaml` and its storage file(s); a bare `.mcap` or `.db3`
file, or a directory whose metadata.yaml is missing, also reads (data/bag_layout.py finds the
files). Uncompressed MCAP (the project's own bags and Jazzy's default) is read here, truncated
files included; sqlite3 storage (Humble's default) and file- or message-compressed bags go
through rosbags (data/bag_storage.py). Payloads are CDR.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any
import warnings

from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.bag_layout import locate
from cloth_bench_ros.data.bag_storage import RosbagsStorage
from cloth_bench_ros.data.errors import BagError, BagWarning
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, POINTCLOUD2
from cloth_bench_ros.data.trial import (
    CLOUD_TOPIC,
    CUSTOM_DATA_PREFIX,
    MCAP_TRIAL_RECORD,
    trial_from_message,
    TRIAL_TOPIC,
    TrialInfo,
)
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk, MAGIC_SIZE, StreamReader
import numpy as np

IRREGULAR_TOLERANCE = 0.25  # an interval off 1/fps by more than this fraction is irregular

_MAGIC = b'\x89MCAP0\r\n'


@dataclass
class CloudStats:
    """What `BagReader.clouds` met on its last pass: nothing is dropped without being counted."""

    frames: int = 0  # clouds yielded
    messages: int = 0  # PointCloud2 messages read (yielded + empty)
    points: int = 0  # points yielded
    nan_points_dropped: int = 0
    empty_clouds_skipped: int = 0  # clouds with no finite point
    irregular_intervals: int = 0  # stamp steps off 1/fps by more than IRREGULAR_TOLERANCE


# --------------------------------------------------------------------------------------- reading


@dataclass
class _McapFile:
    path: Path
    complete: bool  # footer and summary readable
    topics: dict[str, str]
    counts: dict[str, int]
    metadata: dict[str, dict[str, str]]
    start_ns: int | None
    end_ns: int | None
    compression: str
    damage: str | None = None  # where a truncated file stops


def _stamp_from_cdr(cdr: bytes) -> int:
    """Header stamp at the start of a CDR payload whose first field is std_msgs/Header."""
    order = '<' if cdr[1] & 1 else '>'
    sec = int.from_bytes(cdr[4:8], 'little' if order == '<' else 'big', signed=True)
    nsec = int.from_bytes(cdr[8:12], 'little' if order == '<' else 'big')
    return sec * 1_000_000_000 + nsec


def _schema_name(schemas: dict[int, Schema], channel: Channel) -> str:
    schema = schemas.get(channel.schema_id)
    return schema.name if schema is not None else ''


class BagReader:
    """
    Reads a rosbag2 MCAP bag (directory or bare .mcap) in record order.

    Opening validates the files and reads the summaries; `raw_messages` and `clouds` stream the
    data. A truncated file without summary is read up to the damage, with a `BagWarning`.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.stats = CloudStats()
        layout = locate(self.path)
        self.path = layout.path
        if layout.warning:
            self._warn(layout.warning)
        self._bag_meta: dict[str, Any] = dict(layout.metadata or {})
        self._rosbags: RosbagsStorage | None = None
        if layout.rosbags_sources:
            self._rosbags = RosbagsStorage.open(
                self.path, layout.rosbags_storage, layout.rosbags_sources
            )
        self._files = [self._open_file(p) for p in layout.mcap_files]
        self.topics: dict[str, str] = {}
        self.message_counts: dict[str, int] = {}
        if self._rosbags is not None:
            self.topics.update(self._rosbags.topics)
            self.message_counts.update(self._rosbags.counts)
        for topic in self._bag_meta.get('topics', []):
            self.topics[topic['name']] = topic['type']
            self.message_counts[topic['name']] = topic['message_count']
        for f in self._files:
            self.topics.update(f.topics)
            if not self._bag_meta:
                for topic, n in f.counts.items():
                    self.message_counts[topic] = self.message_counts.get(topic, 0) + n
        self._trial: TrialInfo | None | bool = False  # False: not looked up yet

    # -- opening

    def _warn(self, text: str) -> None:
        self.warnings.append(text)
        warnings.warn(text, BagWarning, stacklevel=3)

    def _open_file(self, path: Path) -> _McapFile:
        try:
            with path.open('rb') as f:
                head = f.read(MAGIC_SIZE)
                f.seek(0, os.SEEK_END)
                size = f.tell()
                if head != _MAGIC:
                    raise BagError(f'bag {path} is not an MCAP file (no MCAP magic at the start)')
                try:
                    f.seek(size - MAGIC_SIZE)
                    if f.read(MAGIC_SIZE) != _MAGIC:
                        raise ValueError('no closing magic')
                    f.seek(0)
                    summary = SeekingReader(f).get_summary()
                    complete = True
                except Exception:  # noqa: BLE001 - any failure here means no usable summary
                    summary, complete = None, False
                metadata: dict[str, dict[str, str]] = {}
                if complete:
                    f.seek(0)
                    try:
                        for rec in SeekingReader(f).iter_metadata():
                            metadata[rec.name] = dict(rec.metadata)
                    except Exception as exc:  # noqa: BLE001
                        raise BagError(f'bag {path} is corrupt (metadata: {exc})') from None
        except OSError as exc:
            raise BagError(f'bag {path} cannot be read ({exc.strerror or exc})') from None
        if summary is not None and summary.channels:
            stats = summary.statistics
            topics = {
                ch.topic: _schema_name(summary.schemas, ch) for ch in summary.channels.values()
            }
            counts: dict[str, int] = {}
            if stats is not None:
                for cid, n in stats.channel_message_counts.items():
                    topic = summary.channels[cid].topic
                    counts[topic] = counts.get(topic, 0) + n
            compression = ','.join(
                sorted({c.compression or 'none' for c in summary.chunk_indexes})
            )
            start = stats.message_start_time if stats and stats.message_count else None
            end = stats.message_end_time if stats and stats.message_count else None
            return _McapFile(
                path, True, topics, counts, metadata, start, end, compression or 'none'
            )
        # No summary: scan the data section (a truncated file, or a writer that skipped it).
        scan = _McapFile(path, complete, {}, {}, metadata, None, None, '')
        kinds: set[str] = set()
        for rec, _ in self._records(scan, on_chunk=lambda c: kinds.add(c.compression or 'none')):
            if isinstance(rec, Message):
                scan.start_ns = (
                    rec.log_time if scan.start_ns is None else min(scan.start_ns, rec.log_time)
                )
                scan.end_ns = (
                    rec.log_time if scan.end_ns is None else max(scan.end_ns, rec.log_time)
                )
            elif isinstance(rec, Metadata):
                scan.metadata[rec.name] = dict(rec.metadata)
        scan.compression = ','.join(sorted(kinds)) or 'none'
        if scan.damage and scan.start_ns is None:
            raise BagError(f'bag {path} is corrupt: no message could be read before the damage')
        if scan.damage:
            self._warn(scan.damage)
        return scan

    def _records(
        self, mf: _McapFile, topics: set[str] | None = None, on_chunk: Any = None
    ) -> Iterator[tuple[Any, str]]:
        """
        (record, topic) for Message (topic set) and Metadata records in file order.

        Keeps the file's topic table and message counts current while scanning; stops at the
        damage of an incomplete file (recording `mf.damage`), raises BagError on a complete one.
        """
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        n = 0
        scanning = on_chunk is not None

        def sort(rec: Any) -> Iterator[tuple[Any, str]]:
            nonlocal n
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
                if scanning:
                    mf.topics[rec.topic] = _schema_name(schemas, rec)
            elif isinstance(rec, Message):
                n += 1
                ch = channels.get(rec.channel_id)
                if ch is None:
                    raise ValueError(f'message on unknown channel {rec.channel_id}')
                if scanning:
                    mf.counts[ch.topic] = mf.counts.get(ch.topic, 0) + 1
                if topics is None or ch.topic in topics:
                    yield rec, ch.topic
            elif isinstance(rec, Metadata):
                yield rec, ''

        try:
            with mf.path.open('rb') as f:
                size = os.fstat(f.fileno()).st_size
                reader = StreamReader(f, emit_chunks=True, record_size_limit=max(size, 1))
                for rec in reader.records:
                    if isinstance(rec, (DataEnd, Footer)):
                        return
                    if isinstance(rec, Chunk):
                        if on_chunk is not None:
                            on_chunk(rec)
                        for inner in breakup_chunk(rec, validate_crc=True):
                            yield from sort(inner)
                    else:
                        yield from sort(rec)
        except OSError as exc:
            raise BagError(f'bag {mf.path} cannot be read ({exc.strerror or exc})') from None
        except BagError:
            raise
        except Exception as exc:  # noqa: BLE001 - the mcap library raises many types on bad data
            what = (
                f'{type(exc).__name__}: {exc}'.splitlines()[0] if str(exc) else type(exc).__name__
            )
            if mf.complete:
                raise BagError(f'bag {mf.path} is corrupt after {n} messages ({what})') from None
            if mf.damage is None:
                mf.damage = (
                    f'bag {mf.path} is truncated (no MCAP summary, recording interrupted?); '
                    f'read {n} messages up to the damage ({what})'
                )
            return
        if not mf.complete and mf.damage is None:
            mf.damage = f'bag {mf.path} has no MCAP footer; read {n} messages'

    # -- public surface

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Remove what a file-compressed bag was decompressed into."""
        if self._rosbags is not None:
            self._rosbags.close()

    @property
    def files(self) -> list[Path]:
        """Return the bag's storage files."""
        return self._rosbags.files if self._rosbags is not None else [f.path for f in self._files]

    @property
    def storage(self) -> str:
        """Return the storage and its compression, e.g. `mcap, chunk compression zstd`."""
        if self._rosbags is not None:
            compression = self._rosbags.compression
            return f'{self._rosbags.kind}, ' + (
                'uncompressed' if compression == 'none' else f'compression {compression}'
            )
        return f'mcap, chunk compression {self.compression}'

    @property
    def complete(self) -> bool:
        """Return False if a file had no readable summary (a truncated recording)."""
        return all(f.complete for f in self._files)

    @property
    def metadata_summary(self) -> str:
        """metadata.yaml's version and distro, or why there is none."""
        if not self._bag_meta:
            return 'no metadata.yaml'
        return (
            f'version {self._bag_meta["version"]}, ros_distro'
            f' {self._bag_meta["ros_distro"] or "not set"}'
        )

    @property
    def custom_data(self) -> dict[str, str]:
        return dict(self._bag_meta.get('custom_data') or {})

    @property
    def start_ns(self) -> int | None:
        if self._rosbags is not None:
            return self._rosbags.start_ns
        starts = [f.start_ns for f in self._files if f.start_ns is not None]
        return min(starts) if starts else None

    @property
    def end_ns(self) -> int | None:
        if self._rosbags is not None:
            return self._rosbags.end_ns
        ends = [f.end_ns for f in self._files if f.end_ns is not None]
        return max(ends) if ends else None

    @property
    def compression(self) -> str:
        if self._rosbags is not None:
            return self._rosbags.compression
        return ','.join(sorted({f.compression for f in self._files}))

    @property
    def trial(self) -> TrialInfo | None:
        """Return the trial: metadata.yaml custom_data, else the MCAP record, else TRIAL_TOPIC."""
        if self._trial is False:
            self._trial = self._find_trial()
        return self._trial  # type: ignore[return-value]

    def _find_trial(self) -> TrialInfo | None:
        try:
            custom = self.custom_data
            keys = {
                k[len(CUSTOM_DATA_PREFIX):]: str(v)
                for k, v in custom.items()
                if k.startswith(CUSTOM_DATA_PREFIX)
            }
            if keys:
                return TrialInfo.from_strings(keys)
            for f in self._files:
                if MCAP_TRIAL_RECORD in f.metadata:
                    return TrialInfo.from_strings(f.metadata[MCAP_TRIAL_RECORD])
            if self.topics.get(TRIAL_TOPIC) == DIAGNOSTIC_ARRAY:
                for _, _, _, cdr in self.raw_messages([TRIAL_TOPIC]):
                    return trial_from_message(messages.deserialize(cdr, DIAGNOSTIC_ARRAY))
        except (ValueError, TypeError, KeyError) as exc:
            raise BagError(f'bag {self.path} has invalid trial metadata ({exc})') from None
        return None

    @property
    def cloud_topics(self) -> list[str]:
        """Every PointCloud2 topic of the bag, sorted."""
        return sorted(t for t, m in self.topics.items() if m == POINTCLOUD2)

    def cloud_topic(self, chosen: str | None = None) -> str:
        """Return the PointCloud2 topic to score: `chosen`, else CLOUD_TOPIC, else the only one."""
        clouds = self.cloud_topics
        if chosen:
            if chosen not in clouds:
                what = f'is {self.topics[chosen]}' if chosen in self.topics else 'does not exist'
                raise BagError(
                    f'bag {self.path}: topic {chosen} {what} (PointCloud2 topics: '
                    f'{", ".join(clouds) or "none"})'
                )
            return chosen
        if CLOUD_TOPIC in clouds:
            return CLOUD_TOPIC
        if not clouds:
            raise BagError(f'bag {self.path} has no {POINTCLOUD2} topic')
        if len(clouds) > 1:
            raise BagError(
                f'bag {self.path} has several {POINTCLOUD2} topics ({", ".join(clouds)}); '
                'choose one with --topic'
            )
        return clouds[0]

    def raw_messages(
        self, topics: Iterable[str] | str | None = None
    ) -> Iterator[tuple[str, str, int, bytes]]:
        """(topic, msgtype, stamp_ns, cdr) in record order; stamp = header stamp, else log time."""
        for topic, msgtype, stamp, data in self.logged_messages(topics):
            try:
                if messages.has_header(msgtype) and len(data) >= 12:
                    stamp = _stamp_from_cdr(data)
            except messages.MessageTypeError:
                pass
            yield topic, msgtype, stamp, data

    def logged_messages(
        self, topics: Iterable[str] | str | None = None
    ) -> Iterator[tuple[str, str, int, bytes]]:
        """Yield (topic, msgtype, log_time_ns, cdr) in record order, by MCAP log time."""
        wanted = (
            {topics} if isinstance(topics, str) else (set(topics) if topics is not None else None)
        )
        if self._rosbags is not None:
            yield from self._rosbags.messages(wanted)
        for mf in self._files:
            for rec, topic in self._records(mf, wanted):
                if isinstance(rec, Message):
                    yield (
                        topic,
                        mf.topics.get(topic) or self.topics.get(topic, ''),
                        rec.log_time,
                        rec.data,
                    )

    def clouds(self, topic: str | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """
        (stamp_ns, float64 (n, 3) points) of each non-empty cloud, NaN points dropped.

        Counts go to `self.stats` (reset at each call).
        """
        topic = topic or self.cloud_topic()
        if topic not in self.topics:
            raise BagError(
                f'bag {self.path} has no topic {topic} (topics:'
                f' {", ".join(sorted(self.topics)) or "none"})'
            )
        if self.topics[topic] != POINTCLOUD2:
            raise BagError(
                f'bag {self.path}: topic {topic} is {self.topics[topic]}, not {POINTCLOUD2}'
            )
        trial = self.trial
        period = 1e9 / (trial.fps if trial else 30.0)
        stats = self.stats = CloudStats()
        prev: int | None = None
        for i, (_, _, stamp, cdr) in enumerate(self.raw_messages([topic])):
            try:
                msg = messages.deserialize(cdr, POINTCLOUD2)
            except Exception as exc:  # noqa: BLE001 - rosbags raises several types on bad CDR
                what = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise BagError(
                    f'bag {self.path}: frame {i} on {topic} (stamp {stamp / 1e9:.3f} s) '
                    f'is not a valid PointCloud2 ({what})'
                ) from None
            try:
                pts = pointcloud2.read_xyz(msg)
            except pointcloud2.PointCloudError as exc:
                raise BagError(
                    f'bag {self.path}: frame {i} on {topic} (stamp {stamp / 1e9:.3f} s): {exc}'
                ) from None
            stats.messages += 1
            if prev is not None and abs((stamp - prev) - period) > IRREGULAR_TOLERANCE * period:
                stats.irregular_intervals += 1
            prev = stamp
            pts, dropped = pointcloud2.drop_nan(pts)
            stats.nan_points_dropped += dropped
            if len(pts) == 0:
                stats.empty_clouds_skipped += 1
                continue
            stats.frames += 1
            stats.points += len(pts)
            yield stamp, pts

    def messages(
        self, topics: Iterable[str] | str | None = None
    ) -> Iterator[tuple[str, int, Any]]:
        """(topic, stamp_ns, rosbags message) in record order."""
        for topic, msgtype, stamp, cdr in self.raw_messages(topics):
            try:
                yield topic, stamp, messages.deserialize(cdr, msgtype)
            except Exception as exc:  # noqa: BLE001
                raise BagError(
                    f'bag {self.path}: a {msgtype} message on {topic} does not decode ({exc})'
                ) from None
