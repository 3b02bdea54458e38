"""
rosbag2 metadata.yaml, versions 4 to 9, read as strictly as rosbag2_storage's yaml.hpp.

Fields by version (rosbag2_storage/yaml.hpp): 3 compression_format/mode; 4 offered_qos_profiles
as a YAML string; 5 files; 6 custom_data; 7 type_description_hash; 8 ros_distro; 9
offered_qos_profiles as a YAML sequence with policy names. A field the version requires and the
file lacks, or a count that is not a number, is an error naming the file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypedDict

from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.safe_io import load_yaml_file, UnsafeInputError

MIN_VERSION, MAX_VERSION = 4, 9


class TopicInfo(TypedDict):
    name: str
    type: str  # noqa: A003  (rosbag2's metadata key)
    message_count: int


class BagMetadata(TypedDict):
    version: int
    storage_identifier: str
    message_count: int
    topics: list[TopicInfo]
    relative_file_paths: list[str]
    compression_mode: str
    custom_data: dict[str, str]
    ros_distro: str


def _count(value: Any, what: str, path: Path) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise BagError(f'bag {path}: {what} is {value!r}, not a non-negative whole number')
    return value


def _require(node: Any, key: str, what: str, path: Path) -> Any:
    if not isinstance(node, dict) or key not in node:
        raise BagError(f'bag {path} is not valid rosbag2 metadata (missing key {what}{key})')
    return node[key]


def _topic(node: Any, version: int, path: Path) -> TopicInfo:
    meta = _require(node, 'topic_metadata', 'topics_with_message_count[].', path)
    name = str(_require(meta, 'name', 'topic_metadata.', path))
    msgtype = str(_require(meta, 'type', 'topic_metadata.', path))
    _require(meta, 'serialization_format', 'topic_metadata.', path)
    qos = _require(meta, 'offered_qos_profiles', 'topic_metadata.', path)
    if version >= 9 and not isinstance(qos, list):
        raise BagError(
            f'bag {path}: topic {name}: offered_qos_profiles is not a sequence (version {version})'
        )
    if version < 9 and not isinstance(qos, str):
        raise BagError(
            f'bag {path}: topic {name}: offered_qos_profiles is not a string (version {version})'
        )
    if version >= 7:
        _require(meta, 'type_description_hash', 'topic_metadata.', path)
    count = _count(
        _require(node, 'message_count', f'topic {name}: ', path), f'message_count of {name}', path
    )
    return TopicInfo(name=name, type=msgtype, message_count=count)


def read_metadata(path: Path) -> BagMetadata:
    """Return the parsed `metadata.yaml` at path; BagError naming it if unreadable or malformed."""
    try:
        doc = load_yaml_file(path)
    except UnsafeInputError as exc:
        raise BagError(f'bag {path} is not valid rosbag2 metadata ({exc})') from None
    info = _require(doc, 'rosbag2_bagfile_information', '', path)
    version = _require(info, 'version', '', path)
    if (
        isinstance(version, bool)
        or not isinstance(version, int)
        or not MIN_VERSION <= version <= MAX_VERSION
    ):
        raise BagError(
            f'bag {path}: metadata version {version!r} is not supported '
            f'(rosbag2 versions {MIN_VERSION} to {MAX_VERSION})'
        )
    for key in (
        'storage_identifier',
        'duration',
        'starting_time',
        'relative_file_paths',
        'topics_with_message_count',
        'compression_format',
        'compression_mode',
    ):
        _require(info, key, '', path)
    if version >= 5:
        _require(info, 'files', '', path)
    custom: Any = {}
    if version >= 6:
        custom = _require(info, 'custom_data', '', path) or {}
        if not isinstance(custom, dict):
            raise BagError(f'bag {path}: custom_data is not a mapping')
    distro = str(_require(info, 'ros_distro', '', path) or '') if version >= 8 else ''
    names = info['relative_file_paths']
    if not isinstance(names, list):
        raise BagError(f'bag {path}: relative_file_paths is not a list')
    topics = info['topics_with_message_count'] or []
    if not isinstance(topics, list):
        raise BagError(f'bag {path}: topics_with_message_count is not a list')
    return BagMetadata(
        version=version,
        storage_identifier=str(info['storage_identifier']),
        message_count=_count(_require(info, 'message_count', '', path), 'message_count', path),
        topics=[_topic(t, version, path) for t in topics],
        relative_file_paths=[str(n) for n in names],
        compression_mode=str(info['compression_mode'] or ''),
        custom_data={str(k): str(v) for k, v in custom.items()},
        ros_distro=distro,
    )
