"""
The comparison bag of a run, for Foxglove/RViz, stamped in run time.

Input is what the evaluator kept of each scored real frame: its `FrameScore`, the real points and
the engine's vertices at that time. The bag holds the real cloud, each engine's vertices
(PointCloud2) and mesh (visualization_msgs/Marker TRIANGLE_LIST, red), the gripper targets,
per-frame metrics, and /tf_static for `world`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cloth_bench_ros.core.scene import ClothGrid, SETTLE_DURATION
from cloth_bench_ros.core.trajectory import full_targets, quaternion_xyz
from cloth_bench_ros.data import messages
from cloth_bench_ros.data.bag_writer import BagWriter
from cloth_bench_ros.data.messages import DIAGNOSTIC_ARRAY, POSE_ARRAY, TYPESTORE
import numpy as np

MARKER = 'visualization_msgs/msg/Marker'
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'
REAL_TOPIC = '/cloth_bench/comparison/real/cloud'
TARGETS_TOPIC = '/cloth_bench/comparison/targets'
METRICS_TOPIC = '/cloth_bench/comparison/metrics'


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


def _marker(stamp: int, engine: str, vertices: np.ndarray, faces: np.ndarray) -> Any:
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


def _tf_static() -> Any:
    ts = default_message(
        'geometry_msgs/msg/TransformStamped',
        header=messages.header(0, 'world'),
        child_frame_id='cloth_bench',
    )
    ts.transform.rotation.w = 1.0
    return messages.msg_class(TF_MESSAGE)(transforms=[ts])


def _targets(primitive: str, rate_hz: float, stamp: int) -> Any:
    tg = full_targets(primitive, rate_hz)
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
    path: Path, pairs: list, primitive: str, rate_hz: float
) -> dict[str, int]:
    """Return the comparison bag (see module doc); returns messages per topic."""
    offset = int(round(SETTLE_DURATION * 1e9))
    with BagWriter(path) as bag:
        bag.write_message('/tf_static', _tf_static(), 0)
        real_done: set[int] = set()
        for score, real, vertices in pairs:
            stamp = offset + int(round(score.t * 1e9))
            if score.frame not in real_done:
                real_done.add(score.frame)
                bag.write_cloud(REAL_TOPIC, stamp, real)
                bag.write_message(TARGETS_TOPIC, _targets(primitive, rate_hz, stamp), stamp)
            engine = score.engine
            bag.write_cloud(f'/cloth_bench/comparison/{engine}/cloud', stamp, vertices)
            bag.write_message(
                f'/cloth_bench/comparison/{engine}/mesh',
                _marker(stamp, engine, vertices, grid_for(len(vertices)).faces()),
                stamp,
            )
            bag.write_message(METRICS_TOPIC, _metrics(stamp, score), stamp)
        return bag.close()
