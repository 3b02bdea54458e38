"""
The grippers' targets of a task (core/task_data.py), sampled at the run's rate.

Every axis is a chain of quintic segments; the trajectory is an analytic function of time and
is sampled at t = k * dt, so it is the same at every rate. The full run starts with the task's
settle phase (docs/benchmark.md section 1); `GripperTargets.quintic_start` marks where the motion
begins.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
import math
from typing import Union

from cloth_bench_ros import validation
from cloth_bench_ros.core import scene
from cloth_bench_ros.core.quintic import QuinticChain
from cloth_bench_ros.core.task_data import Axis, load_task, Task
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.options import PRIMITIVES
import numpy as np


class Primitive(str, Enum):
    DYNAMIC = 'dynamic'
    QUASI_STATIC = 'quasi_static'


def parse_primitive(name: str) -> Primitive:
    """Primitive by name; ValueError names the valid ones."""
    try:
        return Primitive(name)
    except ValueError:
        raise InputError(f'unknown primitive {name!r} (valid: {", ".join(PRIMITIVES)})') from None


TaskLike = Union[Task, Primitive, str]
# the shipped task whose metric keys (CD_d or CD_q, ...) a task's window shares
SUFFIX_TASK = {'d': Primitive.DYNAMIC.value, 'q': Primitive.QUASI_STATIC.value}


def as_task(task: TaskLike) -> Task:
    """Return a Task: itself, or the shipped task a primitive names."""
    if isinstance(task, Task):
        return task
    return load_task(parse_primitive(task).value if isinstance(task, str) else task.value)


def _values(axis: Axis, t: np.ndarray) -> np.ndarray:
    """Return an axis's positions at motion times t (a held value: that value)."""
    if isinstance(axis, QuinticChain):
        return axis.evaluate(t)[0]
    return np.full(len(t), axis)


def _motion(task: Task, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return left (n, 3), right (n, 3) and roll (n,) of the task's motion at times t."""
    if task.recorded is not None:
        left, right = task.recorded.at(t)
        return left, right, np.zeros(len(t))
    left = np.stack([_values(a, t) for a in task.left], axis=1)
    right = np.stack([_values(a, t) for a in task.right], axis=1)
    return left, right, _values(task.roll, t)


def sample_times(duration: float, rate_hz: float) -> np.ndarray:
    """Return t = k / rate for k = 0 .. floor(duration * rate), the end included on a step."""
    rate_hz = validation.rate_hz(rate_hz)  # bounded before anything is allocated
    n = int(math.floor(duration * rate_hz + 1e-9)) + 1
    return np.arange(n) / rate_hz


@dataclass(frozen=True)
class GripperTargets:
    """Sampled targets of both grippers: positions (n, 3) in metres, roll/pitch/yaw in radians."""

    t: np.ndarray  # s, from the start of the run (settle phase included)
    left: np.ndarray
    right: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    quintic_start: float  # s, run time at which the quintic part begins
    rate_hz: float

    def __len__(self) -> int:
        return len(self.t)

    @property
    def quintic_index(self) -> int:
        """Index of the first sample of the quintic part."""
        return int(np.searchsorted(self.t, self.quintic_start - 1e-9))

    def stamp_ns(self, k: int) -> int:
        """Integer nanosecond stamp of sample k (exact: k * 1e9 / rate, rounded once)."""
        return round(k * 1_000_000_000 / self.rate_hz)


def sample_quintic(task: TaskLike, rate_hz: float) -> GripperTargets:
    """Return the motion alone, t from 0 at its start (`cloth-bench trajectory`)."""
    task = as_task(task)
    t = sample_times(task.duration, rate_hz)
    left, right, roll = _motion(task, t)
    n = len(t)
    return GripperTargets(
        t, left, right, roll, np.full(n, task.pitch), np.full(n, task.yaw), 0.0, rate_hz
    )


def _settle(task: Task, t: np.ndarray, start: np.ndarray, grasp: np.ndarray) -> np.ndarray:
    """Hold start, move linearly to the grasp pose, hold."""
    s = np.clip((t - task.settle[0]) / task.settle[1], 0.0, 1.0)[:, None]
    return start + s * (grasp - start)


def full_targets(
    task: TaskLike, rate_hz: float, width: float | None = None
) -> GripperTargets:
    """
    Settle phase followed by the motion, sampled at t = k / rate from the run start.

    `width`: the distance between the grasped corners of a cloth of another width than the
    benchmark's (core/cloth_size.py); the right gripper's x moves by the difference.
    """
    task = as_task(task)
    t = sample_times(task.settle_duration + task.duration, rate_hz)
    tq = t - task.settle_duration
    settle = tq < -1e-9
    left, right, roll = _motion(task, tq)
    n = len(t)
    grasp_left, grasp_right = np.array(task.grasp[0]), np.array(task.grasp[1])
    if task.recorded is not None:  # the cloth starts hanging from the grippers' first positions
        # (core/cloth_mesh.py check_start refuses grippers further apart than the cloth allows)
        left[settle], right[settle] = grasp_left, grasp_right
    else:
        left[settle] = _settle(task, t[settle], scene.GRIPPER_START_LEFT, grasp_left)
        right[settle] = _settle(task, t[settle], scene.GRIPPER_START_RIGHT, grasp_right)
        if width is not None and width != scene.CLOTH_WIDTH:
            right[:, 0] += width - scene.CLOTH_WIDTH
    return GripperTargets(
        t,
        left,
        right,
        roll,
        np.full(n, task.pitch),
        np.full(n, task.yaw),
        task.settle_duration,
        rate_hz,
    )


def quaternion_xyz(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of extrinsic X-Y-Z Euler angles (roll about X first)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


CSV_HEADER = 't,left_x,left_y,left_z,left_roll,right_x,right_y,right_z,right_roll'


def to_csv(targets: GripperTargets) -> str:
    """CSV rows with CSV_HEADER: seconds, metres, radians."""
    rows = [CSV_HEADER]
    for k in range(len(targets)):
        lx, ly, lz = targets.left[k]
        rx, ry, rz = targets.right[k]
        r = targets.roll[k]
        rows.append(
            f'{targets.t[k]:.6f},{lx:.9f},{ly:.9f},{lz:.9f},{r:.9f},'
            f'{rx:.9f},{ry:.9f},{rz:.9f},{r:.9f}'
        )
    return '\n'.join(rows) + '\n'
