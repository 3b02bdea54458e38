"""
A recording of a motion of the test's own (test helper): not the paper's, not the project's engine.

A 0.5 x 0.7 m cloth is simulated with MuJoCo's Python API directly (a flexcomp written here, its
top corners moved kinematically) while two grippers lift it, swing it forward and back, lower it
onto a table at 0.75 m and slide it sideways. Its surface, sampled with 1 mm noise, and the table
top are written as PointCloud2 at 30 fps, the grippers as tf frames `left_gripper` and
`right_gripper` on /tf at 60 Hz, by rosbags' Writer and rosbags' own message types (not the
project's writer or codec). `frame` turns it all into a robot-base frame: rotated about z by
`base_yaw_deg` and moved, the clouds and the grippers expressed in it.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from scipy.spatial import cKDTree

FPS = 30.0
TF_HZ = 60.0
TABLE_Z = 0.75  # m, in the world
GRIPPER_Z = 1.55  # m, the grippers' start height in the world
WIDTH, LENGTH = 0.5, 0.7
NX, NZ = 6, 8
REST_S = 0.5  # s hanging still before the motion (recorded)
MOTION_S = 1.5
SETTLE_S = 1.0  # s of settling before the recording starts
STEP_S = 0.002
NOISE = 0.001  # m
START_NS = 1_750_000_000_000_000_000
LINE_YAW_DEG = 20.0  # the gripper line's direction in the world
BASE_YAW_DEG = 35.0
BASE_ORIGIN = np.array([0.4, -0.3, 0.1])  # the robot base in the world
SWING = 0.15  # m, the forward-and-back swing (another value: another motion of the same cloth)


def _smooth(s: np.ndarray | float) -> np.ndarray | float:
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10 - 15 * s + 6 * s * s)


def grippers(t: float, swing: float = SWING) -> tuple[np.ndarray, np.ndarray]:
    """Return the grippers of the test's own motion (world): lift, swing, lower, slide."""
    yaw = math.radians(LINE_YAW_DEG)
    along = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    normal = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    s = float(_smooth((t - REST_S) / MOTION_S))
    offset = (
        normal * swing * math.sin(2 * math.pi * s)
        + np.array([0.0, 0.0, 0.08 * math.sin(math.pi * s) - 0.55 * s])
        + along * 0.1 * s
    )
    left = np.array([0.1, 0.2, GRIPPER_Z]) + offset
    return left, left + WIDTH * along


def _mesh() -> tuple[np.ndarray, np.ndarray]:
    """Rest vertices (hanging from the grippers' start) and triangles, index j * NX + i."""
    left, right = grippers(0.0)
    s = np.linspace(0.0, 1.0, NX)
    rows = [left + s[:, None] * (right - left) - [0, 0, LENGTH * j / (NZ - 1)] for j in range(NZ)]
    tris = []
    for j in range(NZ - 1):
        for i in range(NX - 1):
            a = j * NX + i
            tris += [(a, a + NX, a + 1), (a + 1, a + NX, a + NX + 1)]
    return np.concatenate(rows), np.asarray(tris)


def simulate(swing: float = SWING) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Return the frame times (s), the cloth's vertices (world) per frame, and its triangles."""
    rest, tris = _mesh()
    points = ' '.join(f'{v:.9g}' for v in rest.ravel())
    element = ' '.join(str(int(i)) for i in tris.ravel())
    xml = f"""
<mujoco>
  <option timestep="{STEP_S}" gravity="0 0 -9.81" integrator="Euler"/>
  <worldbody>
    <geom type="box" size="1.5 1.5 0.025" pos="0.3 0.3 {TABLE_Z - 0.025}" friction="0.6"/>
    <flexcomp name="ref" type="direct" dim="2" point="{points}" element="{element}"
              mass="0.2" radius="0.004">
      <contact selfcollide="none" condim="3" friction="0.6"/>
      <edge equality="true" solref="0.004 1" damping="0.002"/>
      <elasticity young="3e4" poisson="0.2" thickness="0.002" elastic2d="bend"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    corners = [0, NX - 1]
    qpos = [m.jnt_qposadr[m.body_jntadr[m.flex_vertbodyid[c]]] for c in corners]
    dofs = [m.jnt_dofadr[m.body_jntadr[m.flex_vertbodyid[c]]] for c in corners]
    n = len(rest)
    times, frames = [], []
    steps_per_frame = int(round(1 / (FPS * STEP_S)))
    total = int(round((SETTLE_S + REST_S + MOTION_S + 0.3) / STEP_S))
    for k in range(total + 1):
        t = k * STEP_S - SETTLE_S  # recording time
        targets = grippers(max(t, 0.0), swing)
        ahead = grippers(max(t + STEP_S, 0.0), swing)
        for c, qa, da in zip(range(2), qpos, dofs):
            d.qpos[qa:qa + 3] = targets[c] - rest[corners[c]]
            d.qvel[da:da + 3] = (ahead[c] - targets[c]) / STEP_S
        if t >= -1e-9 and (k - int(round(SETTLE_S / STEP_S))) % steps_per_frame == 0:
            mujoco.mj_forward(m, d)
            times.append(t)
            frames.append(d.flexvert_xpos[:n].copy())
        mujoco.mj_step(m, d)
    return np.asarray(times), frames, tris


def surface_points(vertices: np.ndarray, tris: np.ndarray, rng, per_triangle: int = 40):
    """Points spread over the triangles (as a camera sees the cloth), with NOISE."""
    a, b, c = (vertices[tris[:, i]] for i in range(3))
    u, v = rng.random((2, len(tris), per_triangle))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = a[:, None] + u[..., None] * (b - a)[:, None] + v[..., None] * (c - a)[:, None]
    return pts.reshape(-1, 3) + rng.normal(0.0, NOISE, (len(tris) * per_triangle, 3))


def table_points(rng, count: int = 1500) -> np.ndarray:
    """Return the table top the camera sees around the cloth."""
    xy = rng.uniform(-0.3, 0.9, (count, 2))
    return np.column_stack([xy, TABLE_Z + rng.normal(0.0, NOISE, count)])


def base_matrix() -> np.ndarray:
    """World from the robot base: turned BASE_YAW_DEG about z, at BASE_ORIGIN."""
    c, s = math.cos(math.radians(BASE_YAW_DEG)), math.sin(math.radians(BASE_YAW_DEG))
    m = np.eye(4)
    m[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    m[:3, 3] = BASE_ORIGIN
    return m


_REFERENCE: dict = {}  # the simulation of each swing, once per process


def write_recording(
    out: Path,
    frame: str = 'world',
    seed: int = 0,
    tf_gap: tuple[float, float] | None = None,
    tf_from: float = 0.0,
    targets_topic: str = '',
    swing: float = SWING,
) -> dict:
    """
    Write the bag; `frame` world or base_link; returns the reference and its noise floor.

    `tf_gap` (s, s): no gripper sample on /tf between these times; `tf_from`: none before it;
    `targets_topic`: the grippers also as a PoseArray topic of that name; `swing`: another
    motion (the forward-and-back swing's amplitude, m). `floor`: the CD of the
    reference's own vertices against the clouds written, over the frames before `t_contact`.
    """
    if swing not in _REFERENCE:
        _REFERENCE[swing] = simulate(swing)
    times, frames, tris = _REFERENCE[swing]
    floors = []
    rng = np.random.default_rng(seed)
    to_frame = np.eye(4) if frame == 'world' else np.linalg.inv(base_matrix())
    ts = get_typestore(Stores.ROS2_JAZZY)
    T = ts.types

    def header(ns: int, frame_id: str):
        return T['std_msgs/msg/Header'](
            stamp=T['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9),
            frame_id=frame_id,
        )

    def cloud(ns: int, pts: np.ndarray):
        data = np.ascontiguousarray(pts, dtype=np.float32)
        field = T['sensor_msgs/msg/PointField']
        return T['sensor_msgs/msg/PointCloud2'](
            header=header(ns, frame), height=1, width=len(data),
            fields=[field(name=n, offset=4 * i, datatype=7, count=1)
                    for i, n in enumerate('xyz')],
            is_bigendian=False, point_step=12, row_step=12 * len(data),
            data=np.frombuffer(data.tobytes(), dtype=np.uint8), is_dense=True,
        )

    def move(p: np.ndarray) -> np.ndarray:
        return p @ to_frame[:3, :3].T + to_frame[:3, 3]

    def transform(ns: int, child: str, p: np.ndarray):
        return T['geometry_msgs/msg/TransformStamped'](
            header=header(ns, frame), child_frame_id=child,
            transform=T['geometry_msgs/msg/Transform'](
                translation=T['geometry_msgs/msg/Vector3'](x=p[0], y=p[1], z=p[2]),
                rotation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )

    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as bag:
        points = bag.add_connection('/points', 'sensor_msgs/msg/PointCloud2', typestore=ts)
        tf = bag.add_connection('/tf', 'tf2_msgs/msg/TFMessage', typestore=ts)
        poses = targets_topic and bag.add_connection(
            targets_topic, 'geometry_msgs/msg/PoseArray', typestore=ts
        )
        messages = []
        for t, vertices in zip(times, frames):
            ns = START_NS + int(round(t * 1e9))
            pts = np.concatenate([surface_points(vertices, tris, rng), table_points(rng)])
            floors.append((t, float(cKDTree(pts).query(vertices)[0].mean())))
            cdr = ts.serialize_cdr(cloud(ns, move(pts)), 'sensor_msgs/msg/PointCloud2')
            messages.append((ns, points, cdr))
        for k in range(int(times[-1] * TF_HZ) + 1):
            t = k / TF_HZ
            ns = START_NS + int(round(t * 1e9))
            left, right = (move(p[None])[0] for p in grippers(t, swing))
            if poses:
                pose, point = T['geometry_msgs/msg/Pose'], T['geometry_msgs/msg/Point']
                still = T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)
                msg = T['geometry_msgs/msg/PoseArray'](header=header(ns, frame), poses=[
                    pose(position=point(x=p[0], y=p[1], z=p[2]), orientation=still)
                    for p in (left, right)])
                messages.append((ns, poses, ts.serialize_cdr(msg, 'geometry_msgs/msg/PoseArray')))
            if t < tf_from or (tf_gap and tf_gap[0] < t < tf_gap[1]):
                continue
            msg = T['tf2_msgs/msg/TFMessage'](transforms=[
                transform(ns, 'left_gripper', left), transform(ns, 'right_gripper', right)])
            messages.append((ns, tf, ts.serialize_cdr(msg, 'tf2_msgs/msg/TFMessage')))
        for ns, connection, cdr in sorted(messages, key=lambda m: m[0]):
            bag.write(connection, ns, cdr)
    return {'times': times, 'frames': frames, 'tris': tris, 'floors': floors}


def noise_floor(floors: list[tuple[float, float]], until_s: float) -> float:
    """Return the mean of the per-frame floors of the frames before `until_s`."""
    return float(np.mean([cd for t, cd in floors if t < until_s - 1e-9]))
