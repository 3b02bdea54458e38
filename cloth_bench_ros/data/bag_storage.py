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
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
import functools
import os
from pathlib import Path
import shutil
import tempfile
import threading

from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.errors import one_line
from rosbags.rosbag2 import Reader
import rosbags.rosbag2.reader

# rosbags decompresses a file-compressed bag into a tempfile.TemporaryDirectory() it names itself
# and removes at close; a process killed before that leaves it behind. The copy is made under a
# name of ours instead (the pid in it), so that the next run can tell an orphan from the copy of a
# live process and remove it. Reader offers no parameter for the directory: its module's
# TemporaryDirectory is replaced, under a lock, only while one compressed bag opens.
DECOMPRESSED_PREFIX = 'cloth-bench-bag-'
_OPENING = threading.Lock()


def decompressed_dirs(pid: int | None = None) -> list[Path]:
    """Return the decompressed copies on disk (of process `pid`, else of every process)."""
    head = f'{DECOMPRESSED_PREFIX}{pid}-' if pid is not None else DECOMPRESSED_PREFIX
    return sorted(Path(tempfile.gettempdir()).glob(f'{head}*'))


def remove_orphans() -> None:
    """Remove the decompressed copies left by processes that are gone (killed mid-run)."""
    for path in decompressed_dirs():
        try:
            pid = int(path.name[len(DECOMPRESSED_PREFIX):].split('-')[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(path, ignore_errors=True)
        except (ValueError, PermissionError):  # not ours, or another user's live process
            continue


def _open_decompressing(source: Path) -> Reader:
    """Return rosbags' Reader opened, a decompressed copy made under DECOMPRESSED_PREFIX."""
    own = functools.partial(
        tempfile.TemporaryDirectory, prefix=f'{DECOMPRESSED_PREFIX}{os.getpid()}-'
    )
    reader = Reader(source)
    with _OPENING:
        remove_orphans()
        rosbags_tmp = rosbags.rosbag2.reader.TemporaryDirectory
        rosbags.rosbag2.reader.TemporaryDirectory = own  # type: ignore[misc, assignment]
        try:
            reader.open()
        finally:
            rosbags.rosbag2.reader.TemporaryDirectory = rosbags_tmp  # type: ignore[misc]
    return reader


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
            reader = _open_decompressing(source)
        except (
            Exception
        ) as exc:  # noqa: BLE001 - rosbags, sqlite3 and zstd raise many types on bad files
            raise BagError(f'bag {self.path} cannot be read ({one_line(exc)})') from None
        keep = reader.compression_mode == 'file'
        if keep:
            self._decompressed[key] = reader
        try:
            yield reader
        finally:
            if not keep:
                reader.close()

    def close(self) -> None:
        """Close the storage and remove the decompressed copies of a file-compressed bag."""
        while self._decompressed:
            with suppress(Exception):  # sqlite3 closes only in its thread; the copy goes anyway
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
                    raise BagError(f'bag {self.path} is corrupt ({one_line(exc)})') from None
