"""
The comparison bag of a run, for Foxglove/RViz, stamped in run time.

Input is what the evaluator kept of each scored real frame: its `FrameScore`, the real points, the
engine's vertices at that time and each vertex's error. The topics are the node graph's and the
live view's (live/error_view.py): the real cloud, each engine's error cloud (PointCloud2 with the
per-vertex `error` field), mesh (visualization_msgs/Marker TRIANGLE_LIST, red) and frame metrics
(Float64MultiArray), the gripper targets, the per-frame DiagnosticArray, the table, and
/tf_static for `world`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cloth_bench_ros.core.scene import (
    ClothGrid,
    TABLE_THICKNESS,
    TABLE_TOP_Z,
    TABLE_X,
    TABLE_Y,
)
from cloth_bench_ros.core.trajectory import full_targets, GripperTargets, quaternion_xyz, TaskLike
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.bag_writer import BagWriter
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, POSE_ARRAY, TYPESTORE
from cloth_bench_ros.live import error_view
import numpy as np

MARKER = 'visualization_msgs/msg/Marker'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'
REAL_TOPIC = error_view.topic(error_view.REAL_CLOUD)
TARGETS_TOPIC = error_view.topic(error_view.TARGETS)
METRICS_TOPIC = error_view.topic(error_view.METRICS)
SCENE_TOPIC = error_view.topic(error_view.SCENE)


def default_message(msgtype: str, **values: Any) -> Any:
    """Return a rosbags message with every field at its ROS default, then `values` set."""
    _, fields = TYPESTORE.fielddefs[msgtype]
    kwargs: dict[str, Any] = {}
    for name, (kind, detail) in fields:
        if name in values:
            kwargs[name] = values[name]
        elif kind == 2:  # nested message: `detail` is its type name
            kwargs[name] = default_message(str(detail))
        elif kind == 1:  # base type
            kwargs[name] = '' if detail[0] == 'string' else False if detail[0] == 'bool' else 0
        elif kind == 4 and detail[0][0] == 1:  # sequence of a base type
            kwargs[name] = np.zeros(
                0, dtype=np.uint8 if detail[0][1] in ('uint8', 'octet') else np.float64
            )
        elif kind == 4:
            kwargs[name] = []
        else:  # fixed array
            kwargs[name] = np.zeros(detail[1])
    return messages.msg_class(msgtype)(**kwargs)


def grid_for(vertex_count: int) -> ClothGrid:
    """Return the cloth grid of an engine's vertex count: the default, or the closest nx x nz."""
    default = ClothGrid()
    if vertex_count == default.nx * default.nz:
        return default
    aspect = default.nz / default.nx
    pairs = [
        (nx, vertex_count // nx)
        for nx in range(2, vertex_count)
        if vertex_count % nx == 0 and vertex_count // nx >= 2
    ]
    if not pairs:
        raise ValueError(f'{vertex_count} vertices do not form a cloth grid')
    nx, nz = min(pairs, key=lambda p: abs(p[1] / p[0] - aspect))
    return ClothGrid(nx, nz)


def cloth_triangles(vertices: np.ndarray, faces: np.ndarray | None) -> np.ndarray:
    """Return the cloth's triangles: `faces` if given, else the grid's of the vertex count."""
    return grid_for(len(vertices)).faces() if faces is None else faces


def mesh_marker(stamp: int, engine: str, vertices: np.ndarray, faces: np.ndarray) -> Any:
    """Return the simulated cloth as a red TRIANGLE_LIST Marker of its triangles."""
    point = messages.msg_class('geometry_msgs/msg/Point')
    tris = vertices[faces.ravel()]
    return default_message(
        MARKER,
        header=messages.header(stamp),
        ns=engine,
        id=0,
        type=11,
        action=0,
        pose=default_message(
            'geometry_msgs/msg/Pose',
            orientation=messages.msg_class('geometry_msgs/msg/Quaternion')(
                x=0.0, y=0.0, z=0.0, w=1.0
            ),
        ),
        scale=messages.msg_class('geometry_msgs/msg/Vector3')(x=1.0, y=1.0, z=1.0),
        color=messages.msg_class('std_msgs/msg/ColorRGBA')(r=1.0, g=0.0, b=0.0, a=0.8),
        points=[point(x=float(x), y=float(y), z=float(z)) for x, y, z in tris],
    )


def table_marker(stamp: int) -> Any:
    """Return the table as a grey CUBE Marker in `world`, its top at the scene's table height."""
    vector = messages.msg_class('geometry_msgs/msg/Vector3')
    return default_message(
        MARKER,
        header=messages.header(stamp),
        ns='table',
        type=1,  # CUBE
        pose=default_message(
            'geometry_msgs/msg/Pose',
            position=messages.msg_class('geometry_msgs/msg/Point')(
                x=sum(TABLE_X) / 2, y=sum(TABLE_Y) / 2, z=TABLE_TOP_Z - TABLE_THICKNESS / 2
            ),
            orientation=messages.msg_class('geometry_msgs/msg/Quaternion')(
                x=0.0, y=0.0, z=0.0, w=1.0
            ),
        ),
        scale=vector(x=TABLE_X[1] - TABLE_X[0], y=TABLE_Y[1] - TABLE_Y[0], z=TABLE_THICKNESS),
        color=messages.msg_class('std_msgs/msg/ColorRGBA')(r=0.6, g=0.6, b=0.6, a=0.5),
    )


def _tf_static() -> Any:
    ts = default_message(
        'geometry_msgs/msg/TransformStamped',
        header=messages.header(0, 'world'),
        child_frame_id='cloth_bench',
    )
    ts.transform.rotation.w = 1.0
    return messages.msg_class(TF_MESSAGE)(transforms=[ts])


def target_poses(tg: GripperTargets, rate_hz: float, stamp: int) -> np.ndarray:
    """Return the [left, right] targets at a run-time stamp as (2, 7): x, y, z, qx, qy, qz, qw."""
    k = int(np.clip(round(stamp / 1e9 * rate_hz), 0, len(tg) - 1))
    q = quaternion_xyz(tg.roll[k], tg.pitch[k], tg.yaw[k])
    return np.array([[*map(float, p[:3]), *q] for p in (tg.left[k], tg.right[k])])


def targets_message(tg: GripperTargets, rate_hz: float, stamp: int) -> Any:
    """Return the PoseArray [left, right] of the grippers' targets at a run-time stamp."""
    k = int(np.clip(round(stamp / 1e9 * rate_hz), 0, len(tg) - 1))
    pose = messages.msg_class('geometry_msgs/msg/Pose')
    qx, qy, qz, qw = quaternion_xyz(tg.roll[k], tg.pitch[k], tg.yaw[k])
    poses = []
    for p in (tg.left[k], tg.right[k]):
        poses.append(
            pose(
                position=messages.msg_class('geometry_msgs/msg/Point')(
                    x=float(p[0]), y=float(p[1]), z=float(p[2])
                ),
                orientation=messages.msg_class('geometry_msgs/msg/Quaternion')(
                    x=qx, y=qy, z=qz, w=qw
                ),
            )
        )
    return messages.msg_class(POSE_ARRAY)(header=messages.header(stamp), poses=poses)


def _metrics(stamp: int, score: Any) -> Any:
    kv = messages.msg_class('diagnostic_msgs/msg/KeyValue')
    status = messages.msg_class('diagnostic_msgs/msg/DiagnosticStatus')(
        level=2 if score.diverged else 0,
        name=f'cloth_bench/{score.engine}/frame',
        message=f'frame {score.frame}',
        hardware_id=score.engine,
        values=[kv(key=k, value=repr(getattr(score, k))) for k in ('frame', 't', 'cd', 'hd')],
    )
    return messages.msg_class(DIAGNOSTIC_ARRAY)(header=messages.header(stamp), status=[status])


def write_comparison_bag(
    path: Path, pairs: list, task: TaskLike, rate_hz: float, faces: np.ndarray | None = None
) -> dict[str, int]:
    """
    Write the comparison bag (see module doc); returns messages per topic.

    pairs: (FrameScore, real points, vertices, per-vertex errors or None) per scored frame;
    faces: the cloth's triangles (a `--cloth-mesh`'s; None: the grid's of the vertex count).
    """
    pc2 = messages.POINTCLOUD2
    tg = full_targets(task, rate_hz)
    offset = int(round(tg.quintic_start * 1e9))
    with BagWriter(path) as bag:
        bag.write_message('/tf_static', _tf_static(), 0)
        bag.write_message(SCENE_TOPIC, table_marker(0), 0)
        real_done: set[int] = set()
        for score, real, vertices, errors in pairs:
            stamp = offset + int(round(score.t * 1e9))
            if score.frame not in real_done:
                real_done.add(score.frame)
                bag.write_cloud(REAL_TOPIC, stamp, real)
                bag.write_message(TARGETS_TOPIC, targets_message(tg, rate_hz, stamp), stamp)
            engine = score.engine
            scored = _Scored(stamp, vertices, errors)
            bag.write(
                error_view.topic(error_view.ERROR_CLOUD, engine),
                pc2,
                stamp,
                error_view.cdr_error_cloud(scored),
            )
            bag.write_message(
                error_view.topic(error_view.MESH, engine),
                mesh_marker(stamp, engine, vertices, cloth_triangles(vertices, faces)),
                stamp,
            )
            bag.write(
                error_view.topic(error_view.FRAME_METRICS_TOPIC, engine),
                error_view.FLOAT64_MULTI_ARRAY,
                stamp,
                error_view.cdr_metrics(
                    error_view.frame_values(score), error_view.FRAME_METRICS
                ),
            )
            bag.write_message(METRICS_TOPIC, _metrics(stamp, score), stamp)
        return bag.close()


class _Scored:
    """The part of a ScoredFrame that an error cloud is made of."""

    def __init__(self, stamp_ns: int, vertices: np.ndarray, errors: np.ndarray | None) -> None:
        self.stamp_ns, self.vertices, self.errors = stamp_ns, vertices, errors
