"""
Quintic Cartesian gripper trajectories of the two primitives (docs/benchmark.md, section 2).

Every axis is a chain of quintic segments; the trajectory is an analytic function of time and
is sampled at t = k * dt, so it is the same at every rate. The full run starts with the settle
phase of docs/benchmark.md section 1; `GripperTargets.quintic_start` marks where the quintic part
begins.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
import math

from cloth_bench_ros import validation
from cloth_bench_ros.core import scene
from cloth_bench_ros.errors import InputError
import numpy as np


class Primitive(str, Enum):
    DYNAMIC = 'dynamic'
    QUASI_STATIC = 'quasi_static'


PRIMITIVES = tuple(p.value for p in Primitive)


def parse_primitive(name: str) -> Primitive:
    """Primitive by name; ValueError names the valid ones."""
    try:
        return Primitive(name)
    except ValueError:
        raise InputError(f'unknown primitive {name!r} (valid: {", ".join(PRIMITIVES)})') from None


@dataclass(frozen=True)
class QuinticSegment:
    """x(t) = a0 + a1 t + ... + a5 t^5 on [0, duration], fixed by (p, v, a) at both ends."""

    duration: float
    start: tuple[float, float, float]
    end: tuple[float, float, float]

    @property
    def coefficients(self) -> np.ndarray:
        p0, v0, a0 = self.start
        p1, v1, a1 = self.end
        T = self.duration
        # Solve for a3, a4, a5 given a0 = p0, a1 = v0, a2 = a0 / 2.
        A = np.array(
            [[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]]
        )
        b = np.array(
            [
                p1 - (p0 + v0 * T + 0.5 * a0 * T**2),
                v1 - (v0 + a0 * T),
                a1 - a0,
            ]
        )
        c3, c4, c5 = np.linalg.solve(A, b)
        return np.array([p0, v0, 0.5 * a0, c3, c4, c5])

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at local times t (not clamped)."""
        c = self.coefficients
        t = np.asarray(t, dtype=float)
        pos = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
        vel = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
        acc = 2 * c[2] + t * (6 * c[3] + t * (12 * c[4] + t * 20 * c[5]))
        return pos, vel, acc


def hold(duration: float, p: float) -> QuinticSegment:
    return QuinticSegment(duration, (p, 0.0, 0.0), (p, 0.0, 0.0))


@dataclass(frozen=True)
class QuinticChain:
    """Segments played one after the other; before 0 the start holds, after the end the end."""

    segments: tuple[QuinticSegment, ...]

    @property
    def duration(self) -> float:
        return float(sum(s.duration for s in self.segments))

    @property
    def breakpoints(self) -> np.ndarray:
        """Return the times at which segments end, from the start of the chain."""
        return np.cumsum([s.duration for s in self.segments])

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        pos, vel, acc = np.empty_like(t), np.empty_like(t), np.empty_like(t)
        ends = self.breakpoints
        starts = ends - np.array([s.duration for s in self.segments])
        # A time on a breakpoint belongs to the segment that ends there (its end conditions hold).
        index = np.clip(np.searchsorted(ends, t - 1e-12, side='left'), 0, len(self.segments) - 1)
        for i, seg in enumerate(self.segments):
            mask = index == i
            if mask.any():
                local = np.clip(t[mask] - starts[i], 0.0, seg.duration)
                pos[mask], vel[mask], acc[mask] = seg.evaluate(local)
        outside = (t < 0.0) | (t > ends[-1])
        vel[outside] = 0.0
        acc[outside] = 0.0
        return pos, vel, acc


@dataclass(frozen=True)
class PrimitiveTrajectory:
    """The quintic part of one primitive: Y, Z and roll chains shared by both grippers."""

    primitive: Primitive
    y: QuinticChain
    z: QuinticChain
    roll: QuinticChain  # radians, unwrapped
    pitch: float  # radians, constant
    yaw: float  # radians, constant
    left_x: float = float(scene.PREGRASP_LEFT[0])
    right_x: float = float(scene.PREGRASP_RIGHT[0])

    @property
    def duration(self) -> float:
        return max(self.y.duration, self.z.duration, self.roll.duration)


def _deg(seg: QuinticSegment) -> QuinticSegment:
    r = math.radians
    return QuinticSegment(
        seg.duration, (r(seg.start[0]), r(seg.start[1]), r(seg.start[2])),
        (r(seg.end[0]), r(seg.end[1]), r(seg.end[2])),
    )


def quintic_part(primitive: Primitive | str) -> PrimitiveTrajectory:
    """Return the quintic part of a primitive, as docs/benchmark.md section 2 tabulates it."""
    primitive = parse_primitive(primitive) if isinstance(primitive, str) else primitive
    y0 = float(scene.PREGRASP_LEFT[1])
    z0 = float(scene.PREGRASP_LEFT[2])
    S = QuinticSegment
    if primitive is Primitive.DYNAMIC:
        zf, zg = z0 + 0.06, z0 - 0.51051
        y = QuinticChain(
            (
                S(1.1, (y0, 0, 0), (y0 - 0.25, -0.7, 3.0)),
                S(1.5, (y0 - 0.25, -0.7, 3.0), (y0 + 0.30, 0.0, -1.0)),
                S(1.3, (y0 + 0.30, 0.0, -1.0), (y0 + 0.15, -0.3, -0.5)),
                S(0.5, (y0 + 0.15, -0.3, -0.5), (y0 - 0.10, 0.0, 0.0)),
            )
        )
        z = QuinticChain(
            (
                S(1.1, (z0, 0, 0), (zf, 0, 0)),
                hold(1.5, zf),
                S(1.3, (zf, 0, 0), (zg, 0, 0.02)),
                hold(0.5, zg),
            )
        )
        roll = QuinticChain(
            tuple(
                _deg(s)
                for s in (
                    S(1.1, (-179.24297822, 0, 0), (-140, 10.8, 180)),
                    S(1.5, (-140, 10.8, 180), (-220, -10, -180)),
                    S(1.3, (-220, -10, -180), (-140, 0, 0)),
                    hold(0.5, -140),
                )
            )
        )
        return PrimitiveTrajectory(
            primitive, y, z, roll, math.radians(-2.93434324), math.radians(42.65659799)
        )
    zm, zt = z0 - 0.05, z0 - 0.31051
    y = QuinticChain((hold(2.0, y0), S(12.0, (y0, 0, 0), (y0 - 0.60, 0, 0))))
    z = QuinticChain(
        (
            S(1.0, (z0, 0, 0), (zm, 0, 0)),
            hold(1.0, zm),
            S(6.0, (zm, 0, 0), (zt, 0, 0.02)),
            hold(6.0, zt),
        )
    )
    roll = QuinticChain((hold(14.0, math.radians(-177.31653135)),))
    return PrimitiveTrajectory(
        primitive, y, z, roll, math.radians(-4.27029547), math.radians(-4.35228107)
    )


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


def sample_quintic(primitive: Primitive | str, rate_hz: float) -> GripperTargets:
    """Return the quintic part alone, t from 0 at its start (`cloth-bench trajectory`)."""
    traj = quintic_part(primitive)
    t = sample_times(traj.duration, rate_hz)
    y, _, _ = traj.y.evaluate(t)
    z, _, _ = traj.z.evaluate(t)
    roll, _, _ = traj.roll.evaluate(t)
    n = len(t)
    left = np.stack([np.full(n, traj.left_x), y, z], axis=1)
    right = np.stack([np.full(n, traj.right_x), y, z], axis=1)
    return GripperTargets(
        t, left, right, roll, np.full(n, traj.pitch), np.full(n, traj.yaw), 0.0, rate_hz
    )


def _settle(t: np.ndarray, start: np.ndarray, pregrasp: np.ndarray) -> np.ndarray:
    """Hold start, move linearly to the pre-grasp pose, hold."""
    s = np.clip((t - scene.SETTLE_HOLD_START) / scene.SETTLE_MOVE, 0.0, 1.0)[:, None]
    return start + s * (pregrasp - start)


def full_targets(
    primitive: Primitive | str, rate_hz: float, width: float | None = None
) -> GripperTargets:
    """
    Settle phase followed by the quintic part, sampled at t = k / rate from the run start.

    `width`: the distance between the grasped corners of a cloth of another width than the
    benchmark's (core/cloth_size.py); the right gripper's x moves by the difference.
    """
    traj = quintic_part(primitive)
    t = sample_times(scene.SETTLE_DURATION + traj.duration, rate_hz)
    tq = t - scene.SETTLE_DURATION
    settle = tq < -1e-9
    y, _, _ = traj.y.evaluate(tq)
    z, _, _ = traj.z.evaluate(tq)
    roll, _, _ = traj.roll.evaluate(tq)
    n = len(t)
    left = np.stack([np.full(n, traj.left_x), y, z], axis=1)
    right = np.stack([np.full(n, traj.right_x), y, z], axis=1)
    left[settle] = _settle(t[settle], scene.GRIPPER_START_LEFT, scene.PREGRASP_LEFT)
    right[settle] = _settle(t[settle], scene.GRIPPER_START_RIGHT, scene.PREGRASP_RIGHT)
    if width is not None and width != scene.CLOTH_WIDTH:
        right[:, 0] += width - scene.CLOTH_WIDTH
    return GripperTargets(
        t,
        left,
        right,
        roll,
        np.full(n, traj.pitch),
        np.full(n, traj.yaw),
        scene.SETTLE_DURATION,
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
