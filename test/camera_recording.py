"""
Turn a bundled bag into what `ros2 bag record` of a depth camera would give (test helper).

Organized PointCloud2 (x, y, z, rgb; NaN where a pixel has no return) in the camera's optical
frame, /tf_static world -> camera_link -> camera_depth_optical_frame, epoch stamps from an
arbitrary start, table and background points in view, no project metadata, and a second
PointCloud2 topic. Written by rosbags' Writer (MCAP or sqlite3 storage, optionally compressed),
not by the project's own writer, so the reader is tested on what an independent writer makes.
"""

from __future__ import annotations

from pathlib import Path

from cloth_bench_ros.core import scene
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.data.messages import header, msg_class, POINTCLOUD2, serialize
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import get_typestore, Stores
from scipy.spatial.transform import Rotation

CAMERA_TOPIC = '/camera/depth/color/points'
IR_TOPIC = '/camera/ir/points'
OPTICAL = 'camera_depth_optical_frame'
EPOCH_START_NS = 1_700_000_123_456_789_012
# world -> optical rotation of the synthetic camera (x right, y down, z along world -y)
R_WORLD_OPTICAL = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])
LINK_ROTATION = np.diag([-1.0, -1.0, 1.0])  # camera_link: yawed 180 deg, looking along world -y


def _transform(parent: str, child: str, translation, rotation: np.ndarray):
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    vec = msg_class('geometry_msgs/msg/Vector3')(
        x=float(translation[0]), y=float(translation[1]), z=float(translation[2])
    )
    quat = msg_class('geometry_msgs/msg/Quaternion')(x=x, y=y, z=z, w=w)
    return msg_class('geometry_msgs/msg/TransformStamped')(
        header=header(EPOCH_START_NS, parent),
        child_frame_id=child,
        transform=msg_class('geometry_msgs/msg/Transform')(translation=vec, rotation=quat),
    )


def organized_cloud(
    stamp: int, points_optical: np.ndarray, height: int, width: int, rng
) -> object:
    """x, y, z, rgb (point_step 20, padding after z) in a height x width grid, NaN where empty."""
    grid = np.full((height * width, 5), np.nan, dtype=np.float32)
    slots = np.sort(rng.choice(height * width, len(points_optical), replace=False))
    grid[slots, :3] = points_optical
    rgb = (rng.integers(0, 256, len(points_optical)) * 0x010101).astype(np.uint32)
    grid[:, 4] = 0.0
    grid[slots, 4] = rgb.view(np.float32)
    field = msg_class('sensor_msgs/msg/PointField')
    fields = [
        field(name=n, offset=o, datatype=7, count=1)
        for n, o in (('x', 0), ('y', 4), ('z', 8), ('rgb', 16))
    ]
    return msg_class(POINTCLOUD2)(
        header=header(stamp, OPTICAL),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=20,
        row_step=20 * width,
        data=np.frombuffer(grid.tobytes(), dtype=np.uint8),
        is_dense=False,
    )


def scene_clutter(rng) -> np.ndarray:
    """Table top and background points the camera sees besides the cloth (world frame)."""
    table = np.column_stack(
        [
            rng.uniform(-0.25, 0.75, 500),
            rng.uniform(-0.85, 0.85, 500),
            scene.TABLE_TOP_Z + rng.normal(0, 0.001, 500),
        ]
    )
    wall = np.column_stack([rng.uniform(-1, 1.5, 200), np.full(200, -2.5), rng.uniform(0, 2, 200)])
    floor = np.column_stack([rng.uniform(-1, 1.5, 100), rng.uniform(-1, 1, 100), np.zeros(100)])
    return np.concatenate([table, wall, floor])


class _RosbagsBag:
    """rosbags' Writer behind a `write(topic, msgtype, stamp_ns, cdr)` call."""

    def __init__(self, out: Path, storage: str, compression: str) -> None:
        plugin = StoragePlugin.SQLITE3 if storage == 'sqlite3' else StoragePlugin.MCAP
        self.writer = Writer(out, version=9, storage_plugin=plugin)
        if compression != 'none':
            mode = CompressionMode.FILE if compression == 'file' else CompressionMode.MESSAGE
            self.writer.set_compression(mode, CompressionFormat.ZSTD)
        self.typestore = get_typestore(Stores.ROS2_JAZZY)
        self.connections: dict[str, object] = {}

    def __enter__(self) -> _RosbagsBag:
        self.writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.writer.close()

    def write(self, topic: str, msgtype: str, stamp_ns: int, cdr: bytes) -> None:
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(
                topic, msgtype, typestore=self.typestore
            )
        self.writer.write(self.connections[topic], stamp_ns, bytes(cdr))


def make_camera_recording(
    source: Path,
    out: Path,
    frames: int | None = None,
    seed: int = 0,
    pre_roll: int = 5,
    noise: float = 0.0,
    storage: str = 'mcap',
    compression: str = 'none',
) -> int:
    """
    Write the camera-like bag; returns the true bag time (ns) of the start of the motion.

    The camera runs `pre_roll` frames before the motion starts (the cloth hangs still: frame 0);
    `noise` (m) is the standard deviation of the sensor noise added to the cloth's points;
    `storage` is mcap or sqlite3, `compression` none, file or message (zstd).
    """
    rng = np.random.default_rng(seed)
    reader = BagReader(source)
    position = scene.CAMERA_POSITION
    optical_in_link = LINK_ROTATION.T @ R_WORLD_OPTICAL.T
    tf = msg_class('tf2_msgs/msg/TFMessage')(
        transforms=[
            _transform('world', 'camera_link', position, LINK_ROTATION),
            _transform('camera_link', OPTICAL, (0.0, 0.0, 0.0), optical_in_link),
        ]
    )
    with _RosbagsBag(out, storage, compression) as bag:
        bag.write('/tf_static', 'tf2_msgs/msg/TFMessage', EPOCH_START_NS - 10**8, serialize(tf))
        clouds = list(reader.clouds())
        period = clouds[1][0] - clouds[0][0]
        clouds = [(-(pre_roll - i) * period, clouds[0][1]) for i in range(pre_roll)] + clouds
        for k, (stamp, points) in enumerate(clouds):
            if frames is not None and k >= frames:
                break
            cloth = points + rng.normal(0.0, noise, points.shape) if noise else points
            world = np.concatenate([cloth, scene_clutter(rng)])
            optical = (world - position) @ R_WORLD_OPTICAL.T
            t = EPOCH_START_NS + stamp
            bag.write(
                CAMERA_TOPIC, POINTCLOUD2, t, serialize(organized_cloud(t, optical, 48, 64, rng))
            )
            if k % 30 == 0:
                bag.write(
                    IR_TOPIC,
                    POINTCLOUD2,
                    t,
                    serialize(organized_cloud(t, optical[:50], 5, 10, rng)),
                )
    return EPOCH_START_NS


TARGETS_TOPIC = '/arm/targets'


def _targets_message(stamp: int, left: np.ndarray, right: np.ndarray) -> object:
    pose, point = msg_class('geometry_msgs/msg/Pose'), msg_class('geometry_msgs/msg/Point')
    quat = msg_class('geometry_msgs/msg/Quaternion')
    return msg_class('geometry_msgs/msg/PoseArray')(
        header=header(stamp, 'world'),
        poses=[
            pose(position=point(x=float(p[0]), y=float(p[1]), z=float(p[2])), orientation=quat(
                x=0.0, y=0.0, z=0.0, w=1.0))
            for p in (left, right)
        ],
    )


def make_repeated_recording(
    source: Path,
    out: Path,
    repetitions: int = 3,
    rest_s: float = 2.0,
    seed: int = 0,
    noise: float = 0.002,
    storage: str = 'mcap',
    targets_rate: float = 0.0,
    jitter_ns: int = 0,
) -> list[int]:
    """
    Write a camera-like recording of the bundled trial done `repetitions` times; true starts (ns).

    Each repetition: `rest_s` of the cloth hanging still, the trial's frames, then `rest_s` of
    the cloth lying still where it ended; the cloth is put back between repetitions unseen (one
    jump). Each repetition's noise is its own (so are the repetitions' clouds, apart from the
    trial's motion); `jitter_ns` shifts each repetition's frames off the camera's clock by up
    to that much. With `targets_rate` > 0, the task's gripper targets are
    recorded on TARGETS_TOPIC at that rate (the start pose at rest before, the end pose after).
    """
    from cloth_bench_ros.core.trajectory import sample_quintic

    rng = np.random.default_rng(seed)
    reader = BagReader(source)
    clouds = list(reader.clouds())
    period = clouds[1][0] - clouds[0][0]
    rest = int(round(rest_s * 1e9 / period))
    position = scene.CAMERA_POSITION
    optical_in_link = LINK_ROTATION.T @ R_WORLD_OPTICAL.T
    tf = msg_class('tf2_msgs/msg/TFMessage')(
        transforms=[
            _transform('world', 'camera_link', position, LINK_ROTATION),
            _transform('camera_link', OPTICAL, (0.0, 0.0, 0.0), optical_in_link),
        ]
    )
    starts = []
    with _RosbagsBag(out, storage, 'none') as bag:
        bag.write('/tf_static', 'tf2_msgs/msg/TFMessage', EPOCH_START_NS - 10**8, serialize(tf))
        t = EPOCH_START_NS
        for _ in range(repetitions):
            shift = int(rng.integers(0, jitter_ns + 1))
            frames = (
                [clouds[0][1]] * rest + [c for _, c in clouds] + [clouds[-1][1]] * rest
            )
            start = t + rest * period + shift
            starts.append(start)
            if targets_rate > 0:  # at rest, the quintic part, at rest
                targets = sample_quintic(reader.trial.primitive, targets_rate)
                step = int(round(1e9 / targets_rate))
                lead = int(rest_s * targets_rate)
                for k in range(-lead, len(targets) + lead):
                    i = min(max(k, 0), len(targets) - 1)
                    stamp = start + k * step
                    msg = _targets_message(stamp, targets.left[i], targets.right[i])
                    bag.write(TARGETS_TOPIC, 'geometry_msgs/msg/PoseArray', stamp, serialize(msg))
            for k, points in enumerate(frames):
                cloth = points + rng.normal(0.0, noise, points.shape) if noise else points
                world = np.concatenate([cloth, scene_clutter(rng)])
                optical = (world - position) @ R_WORLD_OPTICAL.T
                stamp = t + k * period + shift
                cloud = organized_cloud(stamp, optical, 48, 64, rng)
                bag.write(CAMERA_TOPIC, POINTCLOUD2, stamp, serialize(cloud))
            t += len(frames) * period
    return starts


def make_rank_recordings(source: Path, folder: Path) -> Path:
    """One MCAP and one sqlite3 bag of one trial, one MCAP bag of three: five trials in folder."""
    make_camera_recording(source, folder / 'one_mcap', seed=1, pre_roll=30, noise=0.002)
    make_camera_recording(
        source, folder / 'one_sqlite', seed=2, pre_roll=30, noise=0.002, storage='sqlite3'
    )
    make_repeated_recording(source, folder / 'three', rest_s=1.0, seed=3)
    return folder
