"""
Bags the project's own MCAP path does not read, read through rosbags' maintained reader.

ROS 2 Humble records sqlite3 (`.db3`) by default, `ros2 bag record --compression-mode file|message`
writes zstd-compressed files or messages, and a recording killed with SIGKILL leaves its storage
files without metadata.yaml. rosbags.rosbag2 reads all of these; this module adapts it to what
BagReader needs (topics, counts, time range, raw CDR in record order) and turns its errors into one
BagError line naming the bag.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
import threading

from cloth_bench_ros.data.errors import BagError
from rosbags.rosbag2 import Reader


@dataclass
class RosbagsStorage:
    """One bag (a directory with metadata.yaml, or raw storage files) opened with rosbags."""

    path: Path
    kind: str  # storage identifier: sqlite3 or mcap
    sources: list[Path]  # the directory, or each raw .db3 file (no metadata.yaml)
    topics: dict[str, str] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    start_ns: int | None = None
    end_ns: int | None = None
    compression: str = 'none'
    _decompressed: dict[tuple[Path, int], Reader] = field(default_factory=dict, repr=False)

    @classmethod
    def open(  # noqa: A003  (a storage plugin's open, as rosbag2 names it)
        cls, path: Path, kind: str, sources: list[Path]
    ) -> RosbagsStorage:
        """Read every source's connections and time range; BagError if rosbags cannot."""
        storage = cls(path, kind, sources)
        for source in sources:
            with storage._reader(source) as reader:
                for conn in reader.connections:
                    storage.topics[conn.topic] = conn.msgtype
                    storage.counts[conn.topic] = storage.counts.get(conn.topic, 0) + conn.msgcount
                if reader.message_count:
                    storage.start_ns = min(
                        reader.start_time, storage.start_ns or reader.start_time
                    )
                    end = reader.end_time - 1  # rosbags' end is one past the last message
                    storage.end_ns = max(end, storage.end_ns or end)
                if reader.compression_mode:
                    storage.compression = f'{reader.compression_mode}:{reader.compression_format}'
        return storage

    @contextmanager
    def _reader(self, source: Path) -> Iterator[Reader]:
        # rosbags decompresses a file-compressed bag into a temporary copy at each open: that copy
        # is kept until `close` (per thread: sqlite3 connections stay in theirs), other bags
        # reopen.
        key = (source, threading.get_ident())
        if key in self._decompressed:
            yield self._decompressed[key]
            return
        try:
            reader = Reader(source)
            reader.open()
        except (
            Exception
        ) as exc:  # noqa: BLE001 - rosbags, sqlite3 and zstd raise many types on bad files
            raise BagError(f'bag {self.path} cannot be read ({_one_line(exc)})') from None
        keep = reader.compression_mode == 'file'
        if keep:
            self._decompressed[key] = reader
        try:
            yield reader
        finally:
            if not keep:
                reader.close()

    def close(self) -> None:
        """Remove the decompressed copies of a file-compressed bag."""
        while self._decompressed:
            self._decompressed.popitem()[1].close()

    @property
    def files(self) -> list[Path]:
        """Return the storage files on disk."""
        out: list[Path] = []
        for source in self.sources:
            out += (
                sorted(p for p in source.iterdir() if p.name != 'metadata.yaml')
                if source.is_dir()
                else [source]
            )
        return out

    def messages(self, topics: set[str] | None) -> Iterator[tuple[str, str, int, bytes]]:
        """(topic, msgtype, log_time_ns, cdr) of the chosen topics, in record order per source."""
        for source in self.sources:
            with self._reader(source) as reader:
                wanted = [c for c in reader.connections if topics is None or c.topic in topics]
                if not wanted:
                    continue
                try:
                    for conn, log_time, data in reader.messages(wanted):
                        yield conn.topic, conn.msgtype, log_time, bytes(data)
                except Exception as exc:  # noqa: BLE001 - as in _reader
                    raise BagError(f'bag {self.path} is corrupt ({_one_line(exc)})') from None


def _one_line(exc: BaseException) -> str:
    return ' '.join(str(exc).split()) or type(exc).__name__
