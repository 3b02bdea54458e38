"""rosbag2 bags with MCAP storage: the one bag reader and the one bag writer of the project.

A bag is a directory holding `metadata.yaml` and one `.mcap` file (a bare `.mcap` file also
reads). MCAP chunks are zstd-compressed, schemas are `ros2msg` text and payloads CDR, so
`ros2 bag`, Foxglove, `rosbags` and the `mcap` library all open the bags written here.
The trial metadata lives in `metadata.yaml` custom_data (primary, keys `cloth_bench.*`),
mirrored into an MCAP metadata record and the first message on `TRIAL_TOPIC`; see
bags/README.md.
"""

from __future__ import annotations

import json
import os
import threading
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from mcap.records import Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.reader import SeekingReader
from mcap.stream_reader import MAGIC_SIZE, StreamReader, breakup_chunk
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from cloth_bench_ros import validation
from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, POINTCLOUD2
from cloth_bench_ros.safe_io import atomic_write_text

CLOUD_TOPIC = "/cloth_bench/real/cloud"
TARGETS_TOPIC = "/cloth_bench/targets"
TRIAL_TOPIC = "/cloth_bench/real/trial"

METADATA_VERSION = 8  # rosbag2 metadata.yaml version (Iron layout; Humble to Rolling read it)
CUSTOM_DATA_PREFIX = "cloth_bench."  # metadata.yaml custom_data keys of the trial
MCAP_TRIAL_RECORD = "cloth_bench_trial"  # MCAP metadata record mirroring the trial
TRIAL_STATUS_NAME = "cloth_bench/trial"  # DiagnosticStatus.name on TRIAL_TOPIC
ROS_DISTRO = "humble"
IRREGULAR_TOLERANCE = 0.25  # an interval off 1/fps by more than this fraction is irregular

_MAGIC = b"\x89MCAP0\r\n"
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


class BagError(Exception):
    """A bag that cannot be read or written; str() is one line naming the bag and the problem."""


class BagWarning(UserWarning):
    """A bag that reads, but not completely (truncated file, missing metadata.yaml)."""


def _identity() -> list[list[float]]:
    return np.eye(4).tolist()


@dataclass
class TrialInfo:
    """Which real trial a bag holds and how its clouds are expressed."""

    cloth: str
    trial: int
    primitive: str
    change_of_phase_frame: int | None
    source: str
    fps: float = 30.0
    units: str = "m"
    frame_id: str = "world"
    transform: list = field(default_factory=_identity)  # 4x4, applied to the source points

    def __post_init__(self) -> None:
        t = np.asarray(self.transform, dtype=float)
        if t.shape != (4, 4) or not np.isfinite(t).all():
            raise ValueError(f"trial transform must be a finite 4x4 matrix, got shape {t.shape}")
        self.transform = t.tolist()
        self.trial = validation.integer(self.trial, "trial", 0)
        self.fps = validation.positive(self.fps, "trial fps", 10_000.0)
        self.change_of_phase_frame = validation.frame_index(self.change_of_phase_frame, "change_of_phase_frame")

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrialInfo:
        """Inverse of `to_dict`; unknown keys are ignored, missing optional ones defaulted."""
        names = set(cls.__dataclass_fields__)
        missing = [k for k in ("cloth", "trial", "primitive", "source") if k not in data]
        if missing:
            raise ValueError(f"trial metadata lacks {', '.join(missing)}")
        kwargs = {k: v for k, v in data.items() if k in names}
        kwargs.setdefault("change_of_phase_frame", None)
        return cls(**kwargs)

    def to_strings(self) -> dict[str, str]:
        """The string key/values carried by custom_data, MCAP metadata and DiagnosticArray."""
        d = self.to_dict()
        out = {k: str(v) for k, v in d.items() if k not in ("transform", "change_of_phase_frame")}
        out["fps"] = repr(self.fps)
        out["change_of_phase_frame"] = "" if self.change_of_phase_frame is None else str(
            self.change_of_phase_frame
        )
        out["transform"] = json.dumps(self.transform)
        return out

    @classmethod
    def from_strings(cls, data: dict[str, str]) -> TrialInfo:
        """Inverse of `to_strings`; ValueError on malformed values."""
        d: dict[str, Any] = dict(data)
        if "trial" in d:
            d["trial"] = int(d["trial"])
        if "fps" in d:
            d["fps"] = float(d["fps"])
        cop = d.get("change_of_phase_frame", "")
        d["change_of_phase_frame"] = int(cop) if cop not in ("", "None", None) else None
        if "transform" in d:
            d["transform"] = json.loads(d["transform"])
        return cls.from_dict(d)


def trial_message(trial: TrialInfo, stamp_ns: int = 0) -> Any:
    """diagnostic_msgs/DiagnosticArray carrying the trial as key/values (for TRIAL_TOPIC)."""
    kv = messages.msg_class("diagnostic_msgs/msg/KeyValue")
    status = messages.msg_class("diagnostic_msgs/msg/DiagnosticStatus")(
        level=0,
        name=TRIAL_STATUS_NAME,
        message=f"{trial.cloth} trial {trial.trial} {trial.primitive}",
        hardware_id="",
        values=[kv(key=k, value=v) for k, v in trial.to_strings().items()],
    )
    return messages.msg_class(DIAGNOSTIC_ARRAY)(
        header=messages.header(stamp_ns, trial.frame_id), status=[status]
    )


def trial_from_message(msg: Any) -> TrialInfo | None:
    """The trial carried by a DiagnosticArray from `trial_message`, else None."""
    for status in msg.status:
        if status.name == TRIAL_STATUS_NAME:
            return TrialInfo.from_strings({kv.key: kv.value for kv in status.values})
    return None


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
    order = "<" if cdr[1] & 1 else ">"
    sec = int.from_bytes(cdr[4:8], "little" if order == "<" else "big", signed=True)
    nsec = int.from_bytes(cdr[8:12], "little" if order == "<" else "big")
    return sec * 1_000_000_000 + nsec


def _schema_name(schemas: dict[int, Schema], channel: Channel) -> str:
    schema = schemas.get(channel.schema_id)
    return schema.name if schema is not None else ""


class BagReader:
    """Reads a rosbag2 MCAP bag (directory or bare .mcap) in record order.

    Opening validates the files and reads the summaries; `raw_messages` and `clouds` stream the
    data. A truncated file without summary is read up to the damage, with a `BagWarning`.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.warnings: list[str] = []
        self.stats = CloudStats()
        self._bag_meta: dict[str, Any] = {}
        self._files = [self._open_file(p) for p in self._locate()]
        self.topics: dict[str, str] = {}
        self.message_counts: dict[str, int] = {}
        for topic in self._bag_meta.get("topics_with_message_count") or []:
            meta = topic.get("topic_metadata", {})
            self.topics[meta["name"]] = meta["type"]
            self.message_counts[meta["name"]] = int(topic.get("message_count", 0))
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

    def _locate(self) -> list[Path]:
        path = self.path
        if not path.exists():
            raise BagError(f"bag {path} does not exist")
        if path.is_file() and path.name == "metadata.yaml":
            path = self.path = path.parent
        if path.is_file():
            return [path]
        meta_path = path / "metadata.yaml"
        if not meta_path.exists():
            files = sorted(path.glob("*.mcap"))
            if not files:
                raise BagError(f"{path} is not a rosbag2 bag (no metadata.yaml and no .mcap file)")
            self._warn(f"bag {path} has no metadata.yaml (recording interrupted?); reading its .mcap files")
            return files
        try:
            doc = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
            info = doc["rosbag2_bagfile_information"]
            storage = info["storage_identifier"]
            names = [str(x) for x in info["relative_file_paths"]]
            for t in info.get("topics_with_message_count") or []:
                t["topic_metadata"]["name"], t["topic_metadata"]["type"]  # noqa: B018
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError) as exc:
            what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc).splitlines()[0]
            raise BagError(f"bag {meta_path} is not valid rosbag2 metadata ({what})") from None
        if storage != "mcap":
            raise BagError(f"bag {path} uses storage {storage!r}; only mcap is supported")
        if info.get("compression_mode") not in (None, "", "none", "NONE"):
            raise BagError(
                f"bag {path} uses file/message compression {info.get('compression_mode')!r}; "
                "only MCAP chunk compression is supported"
            )
        files = [path / Path(n).name for n in names]
        missing = [str(f) for f in files if not f.exists()]
        if missing:
            raise BagError(f"bag {path} lists missing file(s): {', '.join(missing)}")
        if not files:
            raise BagError(f"bag {path} lists no storage file in metadata.yaml")
        self._bag_meta = info
        return files

    def _open_file(self, path: Path) -> _McapFile:
        try:
            with path.open("rb") as f:
                head = f.read(MAGIC_SIZE)
                f.seek(0, os.SEEK_END)
                size = f.tell()
                if head != _MAGIC:
                    raise BagError(f"bag {path} is not an MCAP file (no MCAP magic at the start)")
                try:
                    f.seek(size - MAGIC_SIZE)
                    if f.read(MAGIC_SIZE) != _MAGIC:
                        raise ValueError("no closing magic")
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
                        raise BagError(f"bag {path} is corrupt (metadata: {exc})") from None
        except OSError as exc:
            raise BagError(f"bag {path} cannot be read ({exc.strerror or exc})") from None
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
            compression = ",".join(sorted({c.compression or "none" for c in summary.chunk_indexes}))
            start = stats.message_start_time if stats and stats.message_count else None
            end = stats.message_end_time if stats and stats.message_count else None
            return _McapFile(path, True, topics, counts, metadata, start, end, compression or "none")
        # No summary: scan the data section (a truncated file, or a writer that skipped it).
        scan = _McapFile(path, complete, {}, {}, metadata, None, None, "")
        kinds: set[str] = set()
        for rec, _ in self._records(scan, on_chunk=lambda c: kinds.add(c.compression or "none")):
            if isinstance(rec, Message):
                scan.start_ns = rec.log_time if scan.start_ns is None else min(scan.start_ns, rec.log_time)
                scan.end_ns = rec.log_time if scan.end_ns is None else max(scan.end_ns, rec.log_time)
            elif isinstance(rec, Metadata):
                scan.metadata[rec.name] = dict(rec.metadata)
        scan.compression = ",".join(sorted(kinds)) or "none"
        if scan.damage and scan.start_ns is None:
            raise BagError(f"bag {path} is corrupt: no message could be read before the damage")
        if scan.damage:
            self._warn(scan.damage)
        return scan

    def _records(self, mf: _McapFile, topics: set[str] | None = None, on_chunk: Any = None) -> Iterator[tuple[Any, str]]:
        """(record, topic) for Message (topic set) and Metadata records in file order.

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
                    raise ValueError(f"message on unknown channel {rec.channel_id}")
                if scanning:
                    mf.counts[ch.topic] = mf.counts.get(ch.topic, 0) + 1
                if topics is None or ch.topic in topics:
                    yield rec, ch.topic
            elif isinstance(rec, Metadata):
                yield rec, ""

        try:
            with mf.path.open("rb") as f:
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
            raise BagError(f"bag {mf.path} cannot be read ({exc.strerror or exc})") from None
        except BagError:
            raise
        except Exception as exc:  # noqa: BLE001 - the mcap library raises many types on bad data
            what = f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__
            if mf.complete:
                raise BagError(f"bag {mf.path} is corrupt after {n} messages ({what})") from None
            if mf.damage is None:
                mf.damage = (
                    f"bag {mf.path} is truncated (no MCAP summary, recording interrupted?); "
                    f"read {n} messages up to the damage ({what})"
                )
            return
        if not mf.complete and mf.damage is None:
            mf.damage = f"bag {mf.path} has no MCAP footer; read {n} messages"

    # -- public surface

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Nothing stays open between reads; kept for symmetry with BagWriter."""

    @property
    def files(self) -> list[Path]:
        return [f.path for f in self._files]

    @property
    def complete(self) -> bool:
        """False if a file had no readable summary (truncated recording)."""
        return all(f.complete for f in self._files)

    @property
    def custom_data(self) -> dict[str, str]:
        return dict(self._bag_meta.get("custom_data") or {})

    @property
    def start_ns(self) -> int | None:
        starts = [f.start_ns for f in self._files if f.start_ns is not None]
        return min(starts) if starts else None

    @property
    def end_ns(self) -> int | None:
        ends = [f.end_ns for f in self._files if f.end_ns is not None]
        return max(ends) if ends else None

    @property
    def compression(self) -> str:
        return ",".join(sorted({f.compression for f in self._files}))

    @property
    def trial(self) -> TrialInfo | None:
        """The trial: metadata.yaml custom_data, else the MCAP record, else TRIAL_TOPIC."""
        if self._trial is False:
            self._trial = self._find_trial()
        return self._trial  # type: ignore[return-value]

    def _find_trial(self) -> TrialInfo | None:
        try:
            custom = self.custom_data
            keys = {k[len(CUSTOM_DATA_PREFIX):]: str(v) for k, v in custom.items() if k.startswith(CUSTOM_DATA_PREFIX)}
            if keys:
                return TrialInfo.from_strings(keys)
            for f in self._files:
                if MCAP_TRIAL_RECORD in f.metadata:
                    return TrialInfo.from_strings(f.metadata[MCAP_TRIAL_RECORD])
            if self.topics.get(TRIAL_TOPIC) == DIAGNOSTIC_ARRAY:
                for _, _, _, cdr in self.raw_messages([TRIAL_TOPIC]):
                    return trial_from_message(messages.deserialize(cdr, DIAGNOSTIC_ARRAY))
        except (ValueError, TypeError, KeyError) as exc:
            raise BagError(f"bag {self.path} has invalid trial metadata ({exc})") from None
        return None

    def cloud_topic(self, preferred: str = CLOUD_TOPIC) -> str:
        """The PointCloud2 topic to score: `preferred` if present, else the only one."""
        clouds = sorted(t for t, m in self.topics.items() if m == POINTCLOUD2)
        if preferred in clouds:
            return preferred
        if not clouds:
            raise BagError(f"bag {self.path} has no {POINTCLOUD2} topic")
        if len(clouds) > 1:
            raise BagError(
                f"bag {self.path} has no {preferred} and several {POINTCLOUD2} topics "
                f"({', '.join(clouds)}); name one"
            )
        return clouds[0]

    def raw_messages(
        self, topics: Iterable[str] | str | None = None
    ) -> Iterator[tuple[str, str, int, bytes]]:
        """(topic, msgtype, stamp_ns, cdr) in record order; stamp = header stamp, else log time."""
        wanted = {topics} if isinstance(topics, str) else (set(topics) if topics is not None else None)
        for mf in self._files:
            for rec, topic in self._records(mf, wanted):
                if not isinstance(rec, Message):
                    continue
                msgtype = mf.topics.get(topic) or self.topics.get(topic, "")
                stamp = rec.log_time
                try:
                    if messages.has_header(msgtype) and len(rec.data) >= 12:
                        stamp = _stamp_from_cdr(rec.data)
                except messages.MessageTypeError:
                    pass
                yield topic, msgtype, stamp, rec.data

    def clouds(self, topic: str | None = None) -> Iterator[tuple[int, np.ndarray]]:
        """(stamp_ns, float64 (n, 3) points) of each non-empty cloud, NaN points dropped.

        Counts go to `self.stats` (reset at each call).
        """
        topic = topic or self.cloud_topic()
        if topic not in self.topics:
            raise BagError(f"bag {self.path} has no topic {topic} (topics: {', '.join(sorted(self.topics)) or 'none'})")
        if self.topics[topic] != POINTCLOUD2:
            raise BagError(f"bag {self.path}: topic {topic} is {self.topics[topic]}, not {POINTCLOUD2}")
        trial = self.trial
        period = 1e9 / (trial.fps if trial else 30.0)
        stats = self.stats = CloudStats()
        prev: int | None = None
        for i, (_, _, stamp, cdr) in enumerate(self.raw_messages([topic])):
            try:
                msg = messages.deserialize(cdr, POINTCLOUD2)
            except Exception as exc:  # noqa: BLE001 - rosbags raises several types on bad CDR
                raise BagError(f"bag {self.path}: message {i} on {topic} is not a valid PointCloud2 ({exc})") from None
            try:
                pts = pointcloud2.read_xyz(msg)
            except pointcloud2.PointCloudError as exc:
                raise BagError(f"bag {self.path}: message {i} on {topic}: {exc}") from None
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

    def messages(self, topics: Iterable[str] | str | None = None) -> Iterator[tuple[str, int, Any]]:
        """(topic, stamp_ns, rosbags message) in record order."""
        for topic, msgtype, stamp, cdr in self.raw_messages(topics):
            try:
                yield topic, stamp, messages.deserialize(cdr, msgtype)
            except Exception as exc:  # noqa: BLE001
                raise BagError(f"bag {self.path}: a {msgtype} message on {topic} does not decode ({exc})") from None


# --------------------------------------------------------------------------------------- writing


class _NoAliasDumper(yaml.SafeDumper):
    def ignore_aliases(self, data: Any) -> bool:
        return True


def _dump_yaml(data: Any) -> str:
    return yaml.dump(data, Dumper=_NoAliasDumper, sort_keys=False)


def _qos_yaml(latched: bool) -> str:
    """offered_qos_profiles as rosbag2 (version 8) stores it: a YAML string of rmw enums."""
    profile = {
        "history": 1,  # keep last
        "depth": 1 if latched else 10,
        "reliability": 1,  # reliable
        "durability": 1 if latched else 2,  # transient local / volatile
        "deadline": {"sec": 0, "nsec": 0},
        "lifespan": {"sec": 0, "nsec": 0},
        "liveliness": 1,  # automatic
        "liveliness_lease_duration": {"sec": 0, "nsec": 0},
        "avoid_ros_namespace_conventions": False,
    }
    return _dump_yaml([profile]).strip()


class BagWriter:
    """Writes a rosbag2 MCAP bag directory; `close()` writes the MCAP summary and metadata.yaml.

    Thread-safe, and `close()` may be called from a signal handler, even one that interrupted a
    `write()` on the same thread: the close then happens as that write returns. Every message
    counted in `written` is in the file once `close()` has run.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        trial: TrialInfo | None = None,
        compression: str = "zstd",
        *,
        chunk_size: int = 1 << 20,
        overwrite: bool = False,
    ) -> None:
        self.path = Path(path)
        self.trial = trial
        if compression not in _COMPRESSION:
            raise BagError(f"bag {self.path}: unknown compression {compression!r} (valid: {', '.join(_COMPRESSION)})")
        if self.path.suffix == ".mcap":
            raise BagError(f"bag {self.path}: give a bag directory, not a .mcap file name")
        if self.path.exists():
            if not self.path.is_dir():
                raise BagError(f"bag {self.path} exists and is not a directory")
            if any(self.path.iterdir()):
                if not overwrite:
                    raise BagError(f"bag {self.path} already exists (not empty)")
                for old in [self.path / "metadata.yaml", *self.path.glob("*.mcap")]:
                    old.unlink(missing_ok=True)
        self.compression = compression
        self.mcap_path = self.path / f"{self.path.name}_0.mcap"
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
            self._stream = self.mcap_path.open("wb")
            self._mcap = McapWriter(self._stream, chunk_size=chunk_size, compression=_COMPRESSION[compression])
            self._mcap.start(profile="ros2", library="cloth_bench_ros")
        except Exception as exc:  # noqa: BLE001 - OSError, or mcap's missing-compressor error
            raise BagError(f"bag {self.path} cannot be created ({exc})") from None
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
                raise BagError(f"bag {self.path}: topic {topic} is {known}, cannot write {msgtype}")
            return self._channels[topic]
        try:
            definition = messages.msgdef(msgtype)
        except messages.MessageTypeError as exc:
            raise BagError(f"bag {self.path}: {exc}") from None
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._mcap.register_schema(msgtype, "ros2msg", definition.encode())
        qos = _qos_yaml(latched=topic == TRIAL_TOPIC)
        self._channels[topic] = self._mcap.register_channel(
            topic, "cdr", self._schemas[msgtype], {"offered_qos_profiles": qos}
        )
        self._types[topic] = msgtype
        self.counts[topic] = 0
        return self._channels[topic]

    def write(self, topic: str, msgtype: str, stamp_ns: int, cdr: bytes) -> bool:
        """Append one CDR message logged at stamp_ns; False (and counted) if already closed."""
        with self._lock:
            self._depth += 1
            try:
                if self._closed or self._close_pending:
                    self.rejected += 1
                    return False
                stamp = int(stamp_ns)
                if stamp < 0:
                    raise BagError(f"bag {self.path}: negative stamp {stamp} ns on {topic}")
                channel = self._channel(topic, msgtype)
                self._mcap.add_message(channel, log_time=stamp, data=bytes(cdr), publish_time=stamp)
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

    def write_cloud(self, topic: str, stamp_ns: int, points: np.ndarray, frame_id: str = "world") -> bool:
        """Write (n, 3) points as an x/y/z float32 PointCloud2 stamped stamp_ns."""
        msg = pointcloud2.create_cloud_xyz32(
            messages.header(stamp_ns, frame_id),
            points,
            messages.msg_class(POINTCLOUD2),
            messages.msg_class("sensor_msgs/msg/PointField"),
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
        """After a failed write (disk full): keep the file as it is, recount it, write metadata.yaml.

        The .mcap then ends at the damage without a summary (BagReader reads it up to there, with a
        warning); `written` and `counts` become what is readable in it, never what was lost.
        """
        with self._lock:
            if (self.path / "metadata.yaml").exists():
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
                    warnings.simplefilter("ignore", BagWarning)
                    reader = BagReader(self.mcap_path)
                counts, self._start, self._end = reader.message_counts, reader.start_ns, reader.end_ns
            except BagError:
                pass  # nothing readable before the damage
            self.counts = {topic: counts.get(topic, 0) for topic in self._types}
            self.written = sum(self.counts.values())
            atomic_write_text(self.path / "metadata.yaml", _dump_yaml({"rosbag2_bagfile_information": self._metadata()}))
            return dict(self.counts)

    def _finish(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._close_pending = False
        info = self._metadata()
        try:
            self._mcap.add_metadata(
                "rosbag2", {"serialized_metadata": _dump_yaml(info), "ROS_DISTRO": ROS_DISTRO}
            )
            self._mcap.finish()
            self._stream.flush()
            os.fsync(self._stream.fileno())
        finally:
            self._stream.close()
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(_dump_yaml({"rosbag2_bagfile_information": info}), encoding="utf-8")
        tmp.replace(self.path / "metadata.yaml")

    def _metadata(self) -> dict[str, Any]:
        start = self._start or 0
        duration = (self._end - self._start) if self._start is not None and self._end is not None else 0
        custom = {}
        if self.trial is not None:
            custom = {CUSTOM_DATA_PREFIX + k: v for k, v in self.trial.to_strings().items()}
        return {
            "version": METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self.written,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": topic,
                        "type": msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": _qos_yaml(latched=topic == TRIAL_TOPIC),
                        "type_description_hash": messages.type_hash(msgtype),
                    },
                    "message_count": self.counts[topic],
                }
                for topic, msgtype in self._types.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.mcap_path.name],
            "files": [
                {
                    "path": self.mcap_path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": self.written,
                }
            ],
            "custom_data": custom or None,
            "ros_distro": ROS_DISTRO,
        }


# --------------------------------------------------------------------------------------- inspect


def describe(path: str | os.PathLike[str], validate: bool = True) -> str:
    """Human-readable summary of a bag (for `cloth-bench bag info`); BagError if unreadable.

    With validate, every cloud is decoded and the frame counts are reported.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", BagWarning)
        reader = BagReader(path)
    size = sum(f.stat().st_size for f in reader.files)
    start, end = reader.start_ns, reader.end_ns
    lines = [
        f"bag:          {reader.path}",
        f"files:        {', '.join(f.name for f in reader.files)} ({size / 1e6:.1f} MB)",
        f"storage:      mcap, chunk compression {reader.compression}",
        f"complete:     {'yes' if reader.complete else 'no (truncated)'}",
    ]
    if start is not None and end is not None:
        lines.append(f"time:         {start / 1e9:.3f} s .. {end / 1e9:.3f} s ({(end - start) / 1e9:.3f} s)")
    lines.append(f"messages:     {sum(reader.message_counts.values())}")
    lines.append("topics:")
    width = max((len(t) for t in reader.topics), default=0)
    for topic in sorted(reader.topics):
        lines.append(f"  {topic:<{width}}  {reader.topics[topic]}  ({reader.message_counts.get(topic, 0)} msgs)")
    trial = reader.trial
    if trial is None:
        lines.append("trial:        none")
    else:
        cop = "none" if trial.change_of_phase_frame is None else str(trial.change_of_phase_frame)
        lines.append(
            f"trial:        {trial.cloth} trial {trial.trial} {trial.primitive}, change of phase {cop}, "
            f"{trial.fps:g} fps, units {trial.units}, frame {trial.frame_id}"
        )
        lines.append(f"source:       {trial.source}")
        if not np.allclose(trial.transform, np.eye(4)):
            lines.append(f"transform:    {json.dumps(trial.transform)}")
    if validate and any(m == POINTCLOUD2 for m in reader.topics.values()):
        topic = reader.cloud_topic()
        sizes = [len(p) for _, p in reader.clouds(topic)]
        s = reader.stats
        pts = f"{min(sizes)}..{max(sizes)} points per frame" if sizes else "no points"
        lines.append(
            f"clouds:       {topic}: {s.frames} frames, {pts}, {s.nan_points_dropped} NaN points dropped, "
            f"{s.empty_clouds_skipped} empty clouds, {s.irregular_intervals} irregular intervals"
        )
    for w in reader.warnings:
        lines.append(f"warning:      {w}")
    return "\n".join(lines)
