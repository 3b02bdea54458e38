"""
The grippers' motion from a recording, as a task file the engines follow (docs/own-recording.md).

`--gripper-frames LEFT,RIGHT` reads the grippers as tf frames of /tf and /tf_static, resolved into
the clouds' frame with data/tf_buffer.py; `--targets-topic T` reads them as the first two poses of
a PoseArray topic. The motion starts at the first cloud of the topic and ends at its last one (or
the grippers' last sample); the grippers must have a sample within MAX_GAP_S of its start and no
gap longer than MAX_GAP_S inside it. One rigid transform (a turn about z and a translation) takes
the recording's frame to the scene's: the left gripper's first position to x = y = 0, the right
one's onto +x, and the table top (`--table-z`, else the plane the cleaning finds in the first
cloud) to the scene's TABLE_TOP_Z; without a table, the left gripper's first height to the
scene's gripper height. Chamfer and Hausdorff distances do not change under it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.cleaning import find_table_z
from cloth_bench_ros.data.bag_reader import BagReader, decode_cloud
from cloth_bench_ros.data.messages import POSE_ARRAY
from cloth_bench_ros.data.tf_buffer import apply, TF_MESSAGE, TF_TOPICS, TfBuffer, TransformError
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.safe_io import atomic_write_text
import numpy as np
import yaml

MAX_GAP_S = 0.1  # s: a longer gap between two gripper samples is refused
TABLE_BELOW_S = 0.05  # m: the table is searched among the points this far below the grippers
# The settle phase before a recorded motion: the cloth hangs still from the grippers' first
# positions (as long as the shipped tasks' settle phase, so that runs line up in time).
SETTLE = {'hold_start': 1.0, 'move': 1.0, 'hold_end': 1.0}


def parse_gripper_frames(text: str | None) -> tuple[str, str] | None:
    """Return (left, right) of `LEFT,RIGHT`, None for '' or None; InputError otherwise."""
    if not text:
        return None
    parts = [p.strip() for p in text.split(',')]
    if len(parts) != 2 or not all(parts) or parts[0] == parts[1]:
        raise InputError(f'--gripper-frames {text!r}: expected two different tf frames LEFT,RIGHT')
    return parts[0], parts[1]


def _tf_buffer(reader: BagReader) -> TfBuffer:
    buffer = TfBuffer()
    tf_topics = [t for t in TF_TOPICS if reader.topics.get(t) == TF_MESSAGE]
    buffer.add_messages((topic, msg) for topic, _, msg in reader.messages(tf_topics))
    return buffer


def _from_tf(
    reader: BagReader, frames: tuple[str, str], target: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return stamps (ns) and left, right (n, 3) in `target` at the left gripper's tf samples."""
    buffer = _tf_buffer(reader)
    for frame in frames:
        if frame not in buffer.frames:
            known = ', '.join(sorted(buffer.frames)) or 'none'
            raise InputError(f'bag {reader.path}: no tf frame {frame} (tf frames: {known})')
    stamps = sorted(set(buffer.stamps(frames[0])) | set(buffer.stamps(frames[1])))
    if len(stamps) < 2:
        raise InputError(
            f'bag {reader.path}: the gripper frames {",".join(frames)} have fewer than 2 '
            'samples on /tf'
        )
    kept, left, right = [], [], []
    for stamp in stamps:
        try:
            pair = [buffer.lookup(target, f, stamp)[:3, 3] for f in frames]
        except TransformError:  # before one gripper's first sample or after its last
            continue
        kept.append(stamp)
        left.append(pair[0])
        right.append(pair[1])
    if len(kept) < 2:
        raise InputError(
            f'bag {reader.path}: the gripper frames {",".join(frames)} cannot be resolved into '
            f'the frame of the clouds, {target}, at 2 common times'
        )
    return np.asarray(kept, dtype=np.int64), np.asarray(left), np.asarray(right)


def _from_targets(
    reader: BagReader, topic: str, target: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return stamps (ns) and the first two poses (left, right) of a PoseArray topic."""
    if reader.topics.get(topic) != POSE_ARRAY:
        raise InputError(f'bag {reader.path} has no {POSE_ARRAY} topic {topic}')
    buffer: TfBuffer | None = None
    stamps, left, right = [], [], []
    for _, stamp, msg in reader.messages([topic]):
        if len(msg.poses) < 2:
            raise InputError(f'bag {reader.path}: {topic} holds a message of fewer than 2 poses')
        pair = np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses[:2]])
        frame = msg.header.frame_id
        if frame and frame.lstrip('/') != target.lstrip('/'):
            buffer = buffer or _tf_buffer(reader)
            try:
                pair = apply(buffer.lookup(target, frame, stamp), pair)
            except TransformError as exc:
                raise InputError(f'bag {reader.path}: {topic}: {exc}') from None
        stamps.append(stamp)
        left.append(pair[0])
        right.append(pair[1])
    if len(stamps) < 2:
        raise InputError(f'bag {reader.path}: {topic} holds fewer than 2 messages')
    return np.asarray(stamps, dtype=np.int64), np.asarray(left), np.asarray(right)


def to_scene_matrix(left0: np.ndarray, right0: np.ndarray, table_z: float | None) -> np.ndarray:
    """Return the 4x4 turn about z and translation that puts the grippers' start on the scene's."""
    dx, dy = float(right0[0] - left0[0]), float(right0[1] - left0[1])
    if math.hypot(dx, dy) < 1e-3:
        raise InputError(
            'the grippers start less than 1 mm apart horizontally: no vertical plane through them'
        )
    angle = math.atan2(dy, dx)
    c, s = math.cos(-angle), math.sin(-angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    turned = m[:3, :3] @ left0
    height = (
        float(scene.GRIPPER_START_LEFT[2]) - float(left0[2])
        if table_z is None
        else scene.TABLE_TOP_Z - table_z
    )
    m[:3, 3] = [-turned[0], -turned[1], height]
    return m


def _first_cloud(reader: BagReader, topic: str) -> tuple[int, np.ndarray, str, int, int]:
    """Return the first cloud's stamp, points and frame, and the topic's first and last stamp."""
    first = None
    last = None
    for index, (_, _, stamp, cdr) in enumerate(reader.raw_messages([topic])):
        if first is None:
            points, frame = decode_cloud(reader.path, topic, index, stamp, cdr)
            first = (stamp, points.reshape(-1, 3), frame)
            low = stamp
        low, last = min(low, stamp), stamp if last is None else max(last, stamp)
    if first is None or last is None:
        raise InputError(f'bag {reader.path}: topic {topic} holds no message')
    return first[0], first[1], first[2], low, last


def recorded_task(
    reader: BagReader,
    topic: str,
    gripper_frames: tuple[str, str] | None,
    targets_topic: str,
    table_z: float | None,
) -> dict[str, Any]:
    """Return the task file (a mapping) of the grippers' recorded motion; InputError if bad."""
    topic = reader.cloud_topic(topic or None)
    _, points, frame, start, end = _first_cloud(reader, topic)
    frame = frame.lstrip('/')
    if gripper_frames:
        stamps, left, right = _from_tf(reader, gripper_frames, frame)
        source = f'tf frames {",".join(gripper_frames)}'
    else:
        stamps, left, right = _from_targets(reader, targets_topic, frame)
        source = f'targets topic {targets_topic}'
    if stamps[0] > start + MAX_GAP_S * 1e9:
        raise InputError(
            f'bag {reader.path}: the grippers ({source}) are missing at the start: their first '
            f'sample is {(stamps[0] - start) / 1e9:.3f} s after the first cloud (at most '
            f'{MAX_GAP_S:g} s)'
        )
    end = min(end, int(stamps[-1]))
    inside = (stamps > start) & (stamps <= end)
    t = np.concatenate([[0.0], (stamps[inside] - start) / 1e9])
    gaps = np.diff(np.concatenate([[max(int(stamps[0]), start)], stamps[inside]])) / 1e9
    if len(gaps) and gaps.max() > MAX_GAP_S:
        at = float(t[int(np.argmax(gaps))])
        raise InputError(
            f'bag {reader.path}: the grippers ({source}) have a gap of {gaps.max():.3f} s at '
            f'{at:.3f} s into the motion (at most {MAX_GAP_S:g} s)'
        )
    at_start = [np.array([np.interp(start, stamps, p[:, i]) for i in range(3)])
                for p in (left, right)]
    left = np.vstack([at_start[0], left[inside]])
    right = np.vstack([at_start[1], right[inside]])
    if len(t) < 2:
        raise InputError(f'bag {reader.path}: the grippers ({source}) have no sample after the '
                         'first cloud')
    if table_z is not None:
        table_source = '--table-z'
    else:
        below = min(left[0, 2], right[0, 2]) - TABLE_BELOW_S
        table_z = find_table_z(points, below)
        table_source = 'the plane found in the first cloud' if table_z is not None else 'none'
    m = to_scene_matrix(left[0], right[0], table_z)
    return {
        'settle': dict(SETTLE),
        'recorded': {
            'source': source,
            'frame': frame,
            'start_ns': int(start),
            'to_scene': [float(v) for v in m.ravel()],
            'table_z': table_z,
            'table_source': table_source,
            't': [float(v) for v in t],
            'left': apply(m, left).tolist(),
            'right': apply(m, right).tolist(),
        },
        'window': 'before_table_contact',
    }


def write_task(path: Path, doc: dict[str, Any]) -> Path:
    """Write a task file (YAML) and return its path."""
    head = (
        "# The grippers' recorded motion, in the scene's frame (cloth-bench; see "
        'docs/own-recording.md).\n'
    )
    atomic_write_text(path, head + yaml.safe_dump(doc, sort_keys=False, width=100))
    return path


def table_line(doc: dict[str, Any]) -> str:
    """Return the one line that says where the table top of a recorded motion comes from."""
    rec = doc['recorded']
    drop = float(scene.GRIPPER_START_LEFT[2]) - scene.TABLE_TOP_Z
    if rec['table_z'] is None:
        return (
            'table: none (no --table-z, and no plane found below the grippers in the first '
            f"cloud): the engines' table lies {drop:.3f} m below the left gripper's start"
        )
    where = f'in {rec["frame"]}, from {rec["table_source"]}'
    return f'table: top at z = {rec["table_z"]:.3f} m {where}'
