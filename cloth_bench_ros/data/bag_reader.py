"""
The one bag reader of the project: any rosbag2 bag a user records, in record order.

A bag is a directory holding `metadata.yaml` and its storage file(s); a bare `.mcap` or `.db3`
file, or a directory whose metadata.yaml is missing, also reads (data/bag_layout.py finds the
files). Uncompressed MCAP (the project's own bags and Jazzy's default) is read here, truncated
files included; sqlite3 storage (Humble's default) and file- or message-compressed bags go
through rosbags (data/bag_storage.py). Payloads are CDR.
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Iterator
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any
import warnings

from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.bag_layout import locate
from cloth_bench_ros.data.bag_mcap import mcap_records, open_mcap_file
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
from cloth_bench_ros.errors import one_line
from mcap.records import Message
import numpy as np

IRREGULAR_TOLERANCE = 0.25  # an interval off 1/fps by more than this fraction is irregular


@dataclass
class CloudStats:
    """What `BagReader.clouds` met on its last pass: nothing is dropped without being counted."""

    frames: int = 0  # clouds yielded
    messages: int = 0  # PointCloud2 messages read (yielded + empty)
    points: int = 0  # points yielded
    nan_points_dropped: int = 0
    empty_clouds_skipped: int = 0  # clouds with no finite point
    irregular_intervals: int = 0  # stamp steps off 1/fps by more than IRREGULAR_TOLERANCE


def _stamp_from_cdr(cdr: bytes) -> int:
    """Header stamp at the start of a CDR payload whose first field is std_msgs/Header."""
    little = bool(cdr[1] & 1)
    sec = int.from_bytes(cdr[4:8], 'little' if little else 'big', signed=True)
    nsec = int.from_bytes(cdr[8:12], 'little' if little else 'big')
    return sec * 1_000_000_000 + nsec


def decode_cloud(
    bag: str | os.PathLike[str], topic: str, index: int, stamp_ns: int, cdr: bytes
) -> tuple[np.ndarray, str]:
    """
    Return the x, y, z points (NaN kept) and frame_id of frame `index` of a bag's cloud topic.

    The one PointCloud2 decode of a bag's frames: a frame that does not decode is a BagError
    naming the bag, the frame, the topic and its stamp.
    """
    where = f'bag {os.fspath(bag)}: frame {index} on {topic} (stamp {stamp_ns / 1e9:.3f} s)'
    try:
        msg = messages.deserialize(cdr, POINTCLOUD2)
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types on bad CDR
        raise BagError(f'{where} is not a valid PointCloud2 ({one_line(exc)})') from None
    try:
        return pointcloud2.read_xyz(msg), msg.header.frame_id
    except pointcloud2.PointCloudError as exc:
        raise BagError(f'{where}: {exc}') from None


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
        self._files = [open_mcap_file(p, self._warn) for p in layout.mcap_files]
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

    def _warn(self, text: str) -> None:
        self.warnings.append(text)
        warnings.warn(text, BagWarning, stacklevel=3)

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
    ) -> Generator[tuple[str, str, int, bytes], None, None]:
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
            for rec, topic in mcap_records(mf, wanted):
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
            pts, _ = decode_cloud(self.path, topic, i, stamp, cdr)
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
