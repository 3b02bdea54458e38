"""
The error on the cloth as ROS 2 messages: one set of topic names and message shapes.

The evaluator's one computation (core.evaluation.ScoredFrame: the real points, the engine's
vertices at the real frame's stamp and each vertex's own term of CD) becomes, for the node graph's
topics, the live viewer stream and the comparison bag alike:

- `/cloth_bench/real/cloud` PointCloud2: the real frame scored;
- `/cloth_bench/<engine>/error_cloud` PointCloud2 with fields x, y, z, error (float32): the scored
  vertices, `error` being each vertex's L1 distance to the nearest real point (m), stamped with
  the real frame;
- `/cloth_bench/<engine>/frame_metrics` std_msgs/Float64MultiArray, per scored real frame:
  `FRAME_METRICS` in that order (t s, CD m, HD m, in_window 1/0);
- `/cloth_bench/<engine>/step_metrics` std_msgs/Float64MultiArray, per simulator step:
  `STEP_METRICS` in that order (t s, step time s, latency s; NaN where not measured).

New metrics are appended at the end of a tuple, never inserted, so an index read once stays
valid; each array's `layout.dim[0].label` names its fields in order.
"""

from __future__ import annotations

import array
from functools import lru_cache
import math
import struct
from typing import Any

from cloth_bench_ros.core import pointcloud2
from cloth_bench_ros.data import messages
import numpy as np

NAMESPACE = '/cloth_bench'
REAL_CLOUD = 'real/cloud'
TARGETS = 'targets'
METRICS = 'metrics'  # the kept DiagnosticArray
SCENE = 'scene'  # the table, a visualization_msgs/Marker
ERROR_CLOUD = 'error_cloud'
MESH = 'mesh'
FRAME_METRICS_TOPIC = 'frame_metrics'
STEP_METRICS_TOPIC = 'step_metrics'
FRAME_METRICS = ('t', 'cd', 'hd', 'in_window')
STEP_METRICS = ('t', 'step_time', 'latency')
FLOAT64_MULTI_ARRAY = 'std_msgs/msg/Float64MultiArray'


def topic(name: str, engine: str | None = None) -> str:
    """Return the absolute topic name: /cloth_bench/<name> or /cloth_bench/<engine>/<name>."""
    return f'{NAMESPACE}/{engine}/{name}' if engine else f'{NAMESPACE}/{name}'


def frame_values(score: Any) -> list[float]:
    """Return a FrameScore's numbers in FRAME_METRICS order."""
    return [float(score.t), float(score.cd), float(score.hd), 1.0 if score.in_window else 0.0]


def step_values(t: float, step_time: float, latency: float | None) -> list[float]:
    """Return one step's numbers in STEP_METRICS order (latency NaN when not measured)."""
    return [float(t), float(step_time), math.nan if latency is None else float(latency)]


def error_values(errors: np.ndarray | None, count: int) -> np.ndarray:
    """Return each vertex's error, NaN for a diverged engine (no error to show)."""
    return np.full(count, np.nan) if errors is None else np.asarray(errors, dtype=float)


def error_cloud(header: Any, scored: Any, cloud_type: type, field_type: type) -> Any:
    """Return the PointCloud2 of a ScoredFrame's vertices with the per-vertex `error` field."""
    vertices = np.asarray(scored.vertices)
    return pointcloud2.create_cloud_xyz_fields(
        header,
        vertices,
        {'error': error_values(scored.errors, len(vertices))},
        cloud_type,
        field_type,
    )


def metrics_array(
    values: list[float],
    fields: tuple[str, ...],
    array_type: type,
    layout_type: type,
    dim_type: type,
) -> Any:
    """Return a Float64MultiArray of `values` whose one dimension's label names the fields."""
    dim = dim_type(label=','.join(fields), size=len(values), stride=len(values))
    if hasattr(array_type, '_fields_and_field_types'):  # rclpy's class: array('d'), not numpy
        data: Any = array.array('d', [float(v) for v in values])
    else:  # rosbags' (and the embedded runtime's): numpy, as its CDR codec wants
        data = np.asarray(values, dtype=np.float64)
    return array_type(layout=layout_type(dim=[dim], data_offset=0), data=data)


# rosbags messages (the live stream and the comparison bag): CDR bytes of one message


def cdr_error_cloud(scored: Any) -> bytes:
    """
    CDR of the error cloud of a ScoredFrame, stamped with its real frame.

    A mesh has the same vertex count in every frame, so the bytes around the stamp and the points
    are serialised once per count (by rosbags) and the stamp and points put in: what rosbags
    writes, without building a message per frame. A cloud with non-finite values (a diverged
    engine: is_dense false) takes the general path.
    """
    vertices = np.asarray(scored.vertices)
    table = np.empty((len(vertices), 4), dtype=np.float32)
    table[:, :3] = vertices
    table[:, 3] = error_values(scored.errors, len(vertices))
    if not np.isfinite(table).all():
        return _serialize_error_cloud(scored.stamp_ns, vertices, table[:, 3])
    before, after = _error_cloud_template(len(vertices))
    return _stamped(before, scored.stamp_ns) + table.tobytes() + after


def _serialize_error_cloud(stamp_ns: int, vertices: np.ndarray, errors: np.ndarray) -> bytes:
    msg = pointcloud2.create_cloud_xyz_fields(
        messages.header(stamp_ns),
        vertices,
        {'error': errors},
        messages.msg_class(messages.POINTCLOUD2),
        messages.msg_class('sensor_msgs/msg/PointField'),
    )
    return messages.serialize(msg, messages.POINTCLOUD2)


@lru_cache(maxsize=16)
def _error_cloud_template(count: int) -> tuple[bytes, bytes]:
    """Return the CDR of a dense error cloud of `count` points before and after its points."""
    marker = np.full((count, 4), 0.5, dtype=np.float32)  # 00 00 00 3f: in no header field
    whole = _serialize_error_cloud(0, marker[:, :3], marker[:, 3])
    start = whole.rfind(marker.tobytes())
    return whole[:start], whole[start + marker.nbytes:]


def _stamped(cdr: bytes, stamp_ns: int) -> bytes:
    """Put a stamp into the CDR of a message whose first field is a std_msgs/Header."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return cdr[:4] + struct.pack('<iI', sec, nanosec) + cdr[12:]


def cdr_poses(stamp_ns: int, poses: np.ndarray) -> bytes:
    """
    CDR of a PoseArray stamped stamp_ns of (n, 7) poses: x, y, z, qx, qy, qz, qw each.

    As rosbags writes it: its bytes before the poses serialised once per count, the doubles put in.
    """
    values = np.ascontiguousarray(poses, dtype='<f8').reshape(-1, 7)
    return _stamped(_poses_template(len(values)), stamp_ns) + values.tobytes()


@lru_cache(maxsize=4)
def _poses_template(count: int) -> bytes:
    m = messages.msg_class
    pose = m('geometry_msgs/msg/Pose')(
        position=m('geometry_msgs/msg/Point')(x=0.0, y=0.0, z=0.0),
        orientation=m('geometry_msgs/msg/Quaternion')(x=0.0, y=0.0, z=0.0, w=0.0),
    )
    msg = m(messages.POSE_ARRAY)(header=messages.header(0), poses=[pose] * count)
    whole = messages.serialize(msg, messages.POSE_ARRAY)
    return whole[: len(whole) - 56 * count]


def cdr_cloud(stamp_ns: int, points: np.ndarray) -> bytes:
    """CDR of a plain x/y/z PointCloud2 (the real frame)."""
    msg = pointcloud2.create_cloud_xyz32(
        messages.header(stamp_ns),
        points,
        messages.msg_class(messages.POINTCLOUD2),
        messages.msg_class('sensor_msgs/msg/PointField'),
    )
    return messages.serialize(msg, messages.POINTCLOUD2)


def cdr_metrics(values: list[float], fields: tuple[str, ...]) -> bytes:
    """
    CDR of a Float64MultiArray of `values` in the order of `fields`.

    The bytes before the numbers depend only on the fields, so they are serialised once (by
    rosbags) and the numbers appended as little-endian doubles: what rosbags writes, without
    building a message per step.
    """
    data = np.asarray(values, dtype='<f8')
    return _metrics_prefix(fields, len(data)) + data.tobytes()


@lru_cache(maxsize=None)
def _metrics_prefix(fields: tuple[str, ...], count: int) -> bytes:
    msg = metrics_array(
        [0.0] * count,
        fields,
        messages.msg_class(FLOAT64_MULTI_ARRAY),
        messages.msg_class('std_msgs/msg/MultiArrayLayout'),
        messages.msg_class('std_msgs/msg/MultiArrayDimension'),
    )
    whole = messages.serialize(msg, FLOAT64_MULTI_ARRAY)
    return whole[: len(whole) - 8 * count]
