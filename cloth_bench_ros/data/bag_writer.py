"""
The one bag writer of the project: rosbag2 bags with MCAP storage.

MCAP chunks are zstd-compressed, schemas are `ros2msg` text and payloads CDR, so `ros2 bag`,
Foxglove, `rosbags` and the `mcap` library all open the bags written here.
"""

from __future__ import annotations

import os
from pathlib import Path
import threading
from typing import Any
import warnings

from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.bag_reader import BagReader
from cloth_bench_ros.data.errors import BagError, BagWarning
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, POINTCLOUD2
from cloth_bench_ros.data.trial import (
    CUSTOM_DATA_PREFIX,
    MCAP_TRIAL_RECORD,
    trial_message,
    TRIAL_TOPIC,
    TrialInfo,
)
from cloth_bench_ros.safe_io import atomic_write_text
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
import numpy as np
import yaml

METADATA_VERSION = 9  # rosbag2 metadata.yaml version that Jazzy writes
ROS_DISTRO = 'jazzy'  # the distro whose layout (version 9) and type hashes (RIHS01) are written
_COMPRESSION = {
    'zstd': CompressionType.ZSTD,
    'lz4': CompressionType.LZ4,
    'none': CompressionType.NONE,
}


class _NoAliasDumper(yaml.SafeDumper):
    def ignore_aliases(self, data: Any) -> bool:
        return True


def _dump_yaml(data: Any) -> str:
    return yaml.dump(data, Dumper=_NoAliasDumper, sort_keys=False)


def _qos_profiles(latched: bool) -> list[dict[str, Any]]:
    """offered_qos_profiles as rosbag2 version 9 stores them: rmw policy names, not enum values."""
    return [
        {
            'history': 'keep_last',
            'depth': 1 if latched else 10,
            'reliability': 'reliable',
            'durability': 'transient_local' if latched else 'volatile',
            'deadline': {'sec': 0, 'nsec': 0},
            'lifespan': {'sec': 0, 'nsec': 0},
            'liveliness': 'automatic',
            'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
            'avoid_ros_namespace_conventions': False,
        }
    ]


def _qos_yaml(latched: bool) -> str:
    """Return the MCAP channel's offered_qos_profiles: the same list dumped to a YAML string."""
    return _dump_yaml(_qos_profiles(latched)).strip()


class BagWriter:
    """
    Writes a rosbag2 MCAP bag directory; `close()` writes the MCAP summary and metadata.yaml.

    Thread-safe, and `close()` may be called from a signal handler, even one that interrupted a
    `write()` on the same thread: the close then happens as that write returns. Every message
    counted in `written` is in the file once `close()` has run.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        trial: TrialInfo | None = None,
        compression: str = 'zstd',
        *,
        chunk_size: int = 1 << 20,
        overwrite: bool = False,
    ) -> None:
        self.path = Path(path)
        self.trial = trial
        if compression not in _COMPRESSION:
            raise BagError(
                f'bag {self.path}: unknown compression {compression!r} (valid:'
                f' {", ".join(_COMPRESSION)})'
            )
        if self.path.suffix == '.mcap':
            raise BagError(f'bag {self.path}: give a bag directory, not a .mcap file name')
        if self.path.exists():
            if not self.path.is_dir():
                raise BagError(f'bag {self.path} exists and is not a directory')
            if any(self.path.iterdir()):
                if not overwrite:
                    raise BagError(f'bag {self.path} already exists (not empty)')
                for old in [self.path / 'metadata.yaml', *self.path.glob('*.mcap')]:
                    old.unlink(missing_ok=True)
        self.compression = compression
        self.mcap_path = self.path / f'{self.path.name}_0.mcap'
        self.written = 0
        self.rejected = 0  # writes refused because the bag was already closed
        self.counts: dict[str, int] = {}
        self._types: dict[str, str] = {}
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._start: int | None = None
        self._end: int | None = None
        self._lock = threading.RLock()
        self._depth = 0  # nesting of write() on the lock-holding thread
        self._close_pending = False
        self._closed = False
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            self._stream = self.mcap_path.open('wb')
            self._mcap = McapWriter(
                self._stream, chunk_size=chunk_size, compression=_COMPRESSION[compression]
            )
            self._mcap.start(profile='ros2', library='cloth_bench_ros')
        except Exception as exc:  # noqa: BLE001 - OSError, or mcap's missing-compressor error
            raise BagError(f'bag {self.path} cannot be created ({exc})') from None
        if trial is not None:
            self._mcap.add_metadata(MCAP_TRIAL_RECORD, trial.to_strings())
            self.write(TRIAL_TOPIC, DIAGNOSTIC_ARRAY, 0, messages.serialize(trial_message(trial)))

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def _channel(self, topic: str, msgtype: str) -> int:
        known = self._types.get(topic)
        if known is not None:
            if known != msgtype:
                raise BagError(
                    f'bag {self.path}: topic {topic} is {known}, cannot write {msgtype}'
                )
            return self._channels[topic]
        try:
            definition = messages.msgdef(msgtype)
        except messages.MessageTypeError as exc:
            raise BagError(f'bag {self.path}: {exc}') from None
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._mcap.register_schema(
                msgtype, 'ros2msg', definition.encode()
            )
        metadata = {
            'offered_qos_profiles': _qos_yaml(latched=topic == TRIAL_TOPIC),
            'topic_type_hash': messages.type_hash(msgtype),
        }
        self._channels[topic] = self._mcap.register_channel(
            topic, 'cdr', self._schemas[msgtype], metadata
        )
        self._types[topic] = msgtype
        self.counts[topic] = 0
        return self._channels[topic]

    def write(
        self, topic: str, msgtype: str, stamp_ns: int, cdr: bytes, log_time_ns: int | None = None
    ) -> bool:
        """
        Append one CDR message logged at log_time_ns (default stamp_ns); False if already closed.

        rosbag2 logs the receive time; a recorder passes it as log_time_ns (the header stamp stays
        in the message). Refused writes are counted in `rejected`.
        """
        with self._lock:
            self._depth += 1
            try:
                if self._closed or self._close_pending:
                    self.rejected += 1
                    return False
                stamp = int(stamp_ns if log_time_ns is None else log_time_ns)
                if stamp < 0:
                    raise BagError(f'bag {self.path}: negative stamp {stamp} ns on {topic}')
                channel = self._channel(topic, msgtype)
                self._mcap.add_message(
                    channel, log_time=stamp, data=bytes(cdr), publish_time=stamp
                )
                self.written += 1
                self.counts[topic] += 1
                self._start = stamp if self._start is None else min(self._start, stamp)
                self._end = stamp if self._end is None else max(self._end, stamp)
                return True
            finally:
                self._depth -= 1
                if self._close_pending and self._depth == 0:
                    self._finish()

    def write_message(self, topic: str, msg: Any, stamp_ns: int) -> bool:
        """Serialise a rosbags message and `write` it."""
        return self.write(topic, msg.__msgtype__, stamp_ns, messages.serialize(msg))

    def write_cloud(
        self, topic: str, stamp_ns: int, points: np.ndarray, frame_id: str = 'world'
    ) -> bool:
        """Write (n, 3) points as an x/y/z float32 PointCloud2 stamped stamp_ns."""
        msg = pointcloud2.create_cloud_xyz32(
            messages.header(stamp_ns, frame_id),
            points,
            messages.msg_class(POINTCLOUD2),
            messages.msg_class('sensor_msgs/msg/PointField'),
        )
        return self.write(topic, POINTCLOUD2, stamp_ns, messages.serialize(msg, POINTCLOUD2))

    def flush(self) -> None:
        """Finish the open chunk and push it to the OS (bounds what a hard kill can lose)."""
        with self._lock:
            if not self._closed:
                self._mcap.flush()

    def close(self) -> dict[str, int]:
        """Finalise (MCAP summary, metadata.yaml); idempotent; returns messages per topic."""
        with self._lock:
            if self._depth > 0:  # a signal handler interrupted write() on this thread
                self._close_pending = True
            else:
                self._finish()
            return dict(self.counts)

    def abandon(self) -> dict[str, int]:
        """
        After a failed write (disk full): keep the file as it is, recount it, write metadata.yaml.

        The .mcap then ends at the damage without a summary (BagReader reads it up to there, with a
        warning); `written` and `counts` become what is readable in it, never what was lost.
        """
        with self._lock:
            if (self.path / 'metadata.yaml').exists():
                return dict(self.counts)  # finalised before the failure
            self._closed = True
            try:
                self._stream.close()
            except OSError:
                pass  # the bytes that did not fit are lost; the file holds a prefix of the stream
            counts: dict[str, int] = {}
            self._start = self._end = None
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter('ignore', BagWarning)
                    with BagReader(self.mcap_path) as reader:
                        counts, self._start, self._end = (
                            reader.message_counts,
                            reader.start_ns,
                            reader.end_ns,
                        )
            except BagError:
                pass  # nothing readable before the damage
            self.counts = {topic: counts.get(topic, 0) for topic in self._types}
            self.written = sum(self.counts.values())
            atomic_write_text(
                self.path / 'metadata.yaml',
                _dump_yaml({'rosbag2_bagfile_information': self._metadata()}),
            )
            return dict(self.counts)

    def _finish(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._close_pending = False
        info = self._metadata()
        try:
            self._mcap.add_metadata('rosbag2', {'serialized_metadata': _dump_yaml(info)})
            self._mcap.finish()
            self._stream.flush()
            os.fsync(self._stream.fileno())
        finally:
            self._stream.close()
        tmp = self.path / 'metadata.yaml.tmp'
        tmp.write_text(_dump_yaml({'rosbag2_bagfile_information': info}), encoding='utf-8')
        tmp.replace(self.path / 'metadata.yaml')

    def _metadata(self) -> dict[str, Any]:
        start = self._start or 0
        duration = (
            (self._end - self._start) if self._start is not None and self._end is not None else 0
        )
        custom = {}
        if self.trial is not None:
            custom = {CUSTOM_DATA_PREFIX + k: v for k, v in self.trial.to_strings().items()}
        return {
            'version': METADATA_VERSION,
            'storage_identifier': 'mcap',
            'duration': {'nanoseconds': duration},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': self.written,
            'topics_with_message_count': [
                {
                    'topic_metadata': {
                        'name': topic,
                        'type': msgtype,
                        'serialization_format': 'cdr',
                        'offered_qos_profiles': _qos_profiles(latched=topic == TRIAL_TOPIC),
                        'type_description_hash': messages.type_hash(msgtype),
                    },
                    'message_count': self.counts[topic],
                }
                for topic, msgtype in self._types.items()
            ],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [self.mcap_path.name],
            'files': [
                {
                    'path': self.mcap_path.name,
                    'starting_time': {'nanoseconds_since_epoch': start},
                    'duration': {'nanoseconds': duration},
                    'message_count': self.written,
                }
            ],
            'custom_data': custom or None,
            'ros_distro': ROS_DISTRO,
        }
