"""
The MCAP files of a bag, read with the mcap library: summaries, and records in file order.

A complete file is read through its summary; a file without one (a recording interrupted, or a
writer that skipped it) is scanned up to its damage, which is reported rather than lost.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
import os
from pathlib import Path
from typing import Any

from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.errors import one_line
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk, MAGIC_SIZE, StreamReader

_MAGIC = b'\x89MCAP0\r\n'


@dataclass
class McapFile:
    """One MCAP file of a bag: its topics, counts, metadata records and time range."""

    path: Path
    complete: bool  # footer and summary readable
    topics: dict[str, str]
    counts: dict[str, int]
    metadata: dict[str, dict[str, str]]
    start_ns: int | None
    end_ns: int | None
    compression: str
    damage: str | None = None  # where a truncated file stops


def _schema_name(schemas: dict[int, Schema], channel: Channel) -> str:
    schema = schemas.get(channel.schema_id)
    return schema.name if schema is not None else ''


def open_mcap_file(path: Path, warn: Callable[[str], None]) -> McapFile:
    """Return a file's summary, or what a scan up to its damage found (`warn` told of it)."""
    try:
        with path.open('rb') as f:
            head = f.read(MAGIC_SIZE)
            f.seek(0, os.SEEK_END)
            size = f.tell()
            if head != _MAGIC:
                raise BagError(f'bag {path} is not an MCAP file (no MCAP magic at the start)')
            try:
                f.seek(size - MAGIC_SIZE)
                complete = f.read(MAGIC_SIZE) == _MAGIC
                if complete:
                    f.seek(0)
                    summary = SeekingReader(f).get_summary()
            except Exception:  # noqa: BLE001 - any failure here means no usable summary
                complete = False
            if not complete:
                summary = None
            metadata: dict[str, dict[str, str]] = {}
            if complete:
                f.seek(0)
                try:
                    for rec in SeekingReader(f).iter_metadata():
                        metadata[rec.name] = dict(rec.metadata)
                except Exception as exc:  # noqa: BLE001
                    raise BagError(f'bag {path} is corrupt (metadata: {one_line(exc)})') from None
    except OSError as exc:
        raise BagError(f'bag {path} cannot be read ({exc.strerror or exc})') from None
    if summary is not None and summary.channels:
        stats = summary.statistics
        topics = {ch.topic: _schema_name(summary.schemas, ch) for ch in summary.channels.values()}
        counts: dict[str, int] = {}
        if stats is not None:
            for cid, n in stats.channel_message_counts.items():
                topic = summary.channels[cid].topic
                counts[topic] = counts.get(topic, 0) + n
        compression = ','.join(sorted({c.compression or 'none' for c in summary.chunk_indexes}))
        start = stats.message_start_time if stats and stats.message_count else None
        end = stats.message_end_time if stats and stats.message_count else None
        return McapFile(path, True, topics, counts, metadata, start, end, compression or 'none')
    # No summary: scan the data section (a truncated file, or a writer that skipped it).
    scan = McapFile(path, complete, {}, {}, metadata, None, None, '')
    kinds: set[str] = set()
    for rec, _ in mcap_records(scan, on_chunk=lambda c: kinds.add(c.compression or 'none')):
        if isinstance(rec, Message):
            scan.start_ns = (
                rec.log_time if scan.start_ns is None else min(scan.start_ns, rec.log_time)
            )
            scan.end_ns = rec.log_time if scan.end_ns is None else max(scan.end_ns, rec.log_time)
        elif isinstance(rec, Metadata):
            scan.metadata[rec.name] = dict(rec.metadata)
    scan.compression = ','.join(sorted(kinds)) or 'none'
    if scan.damage and scan.start_ns is None:
        raise BagError(f'bag {path} is corrupt: no message could be read before the damage')
    if scan.damage:
        warn(scan.damage)
    return scan


def mcap_records(
    mf: McapFile, topics: set[str] | None = None, on_chunk: Any = None
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
            if ch is None:  # caught below: the file is damaged here
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
        what = one_line(exc, with_type=True)
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
