"""
A small tf2 buffer: the transforms of a bag's /tf_static and /tf, looked up as tf2 does.

Each child frame has one parent. Static transforms hold at every time; dynamic ones are
interpolated between the two samples around the asked time (linear translation, slerp rotation)
and never extrapolated (tf2's ExtrapolationException); time 0 asks for the latest common time.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from typing import Any

from cloth_bench_ros.data.messages import stamp_ns
from cloth_bench_ros.errors import ClothBenchError
import numpy as np

TF_TOPICS = ('/tf_static', '/tf')
TF_MESSAGE = 'tf2_msgs/msg/TFMessage'


class TransformError(ClothBenchError, ValueError):
    """A frame that cannot be resolved to the target frame; str() names the frame."""


def _strip(frame: str) -> str:
    return frame[1:] if frame.startswith('/') else frame  # tf2 ignores a leading slash


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """3x3 rotation of a (normalised) quaternion."""
    q = np.array([x, y, z, w], dtype=float)
    n = np.linalg.norm(q)
    if not np.isfinite(n) or n < 1e-9:
        raise TransformError(f'quaternion {q.tolist()} cannot be normalised')
    x, y, z, w = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _slerp(q0: np.ndarray, q1: np.ndarray, w: float) -> np.ndarray:
    q0, q1 = q0 / np.linalg.norm(q0), q1 / np.linalg.norm(q1)
    dot = float(q0 @ q1)
    if dot < 0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + w * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(dot)
    return (np.sin((1 - w) * theta) * q0 + np.sin(w * theta) * q1) / np.sin(theta)


def _matrix(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quaternion_matrix(*q)
    m[:3, 3] = t
    return m


class TfBuffer:
    """Parent links and their transforms; `lookup(target, source, stamp)` maps source to target."""

    def __init__(self) -> None:
        self._parent: dict[str, str] = {}
        self._static: dict[str, np.ndarray] = {}
        self._dynamic: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {}

    def set_transform(self, msg: Any, static: bool) -> None:
        """Add a geometry_msgs/TransformStamped (child_frame_id expressed in header.frame_id)."""
        child, parent = _strip(msg.child_frame_id), _strip(msg.header.frame_id)
        tr, rot = msg.transform.translation, msg.transform.rotation
        t = np.array([tr.x, tr.y, tr.z], dtype=float)
        q = np.array([rot.x, rot.y, rot.z, rot.w], dtype=float)
        self._parent[child] = parent
        if static:
            self._static[child] = _matrix(t, q)
            self._dynamic.pop(child, None)
        else:
            samples = self._dynamic.setdefault(child, [])
            bisect.insort(samples, (stamp_ns(msg.header.stamp), t, q), key=lambda s: s[0])

    def add_messages(self, items: Iterable[tuple[str, Any]]) -> None:
        """(topic, tf2_msgs/TFMessage) pairs as a bag holds them on /tf_static and /tf."""
        for topic, msg in items:
            for transform in msg.transforms:
                self.set_transform(transform, static=topic == '/tf_static')

    def stamps(self, frame: str) -> list[int]:
        """Return, in ns and in order, when a frame's own /tf samples were taken ([]: static)."""
        return [s[0] for s in self._dynamic.get(_strip(frame), [])]

    @property
    def frames(self) -> set[str]:
        return set(self._parent) | set(self._parent.values())

    def _link(self, child: str, stamp: int) -> np.ndarray:
        if child in self._static:
            return self._static[child]
        samples = self._dynamic[child]
        stamps = [s[0] for s in samples]
        if stamp == 0:
            return _matrix(samples[-1][1], samples[-1][2])
        i = bisect.bisect_left(stamps, stamp)
        if i < len(stamps) and stamps[i] == stamp:
            return _matrix(samples[i][1], samples[i][2])
        if i == 0 or i == len(stamps):
            raise TransformError(
                f'frame {child}: no transform to {self._parent[child]} at {stamp / 1e9:.3f} s '
                f'(extrapolation; /tf covers {stamps[0] / 1e9:.3f} .. {stamps[-1] / 1e9:.3f} s)'
            )
        (s0, t0, q0), (s1, t1, q1) = samples[i - 1], samples[i]
        w = (stamp - s0) / (s1 - s0)
        return _matrix(t0 + w * (t1 - t0), _slerp(q0, q1, w))

    def _chain(self, frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in self._parent:
            chain.append(self._parent[chain[-1]])
            if len(chain) > 1000:
                raise TransformError(f'frame {frame}: the tf tree has a loop')
        return chain

    def lookup(self, target: str, source: str, stamp: int = 0) -> np.ndarray:
        """Return the 4x4 matrix from `source` to `target` at `stamp`; TransformError if none."""
        target, source = _strip(target), _strip(source)
        if not source:
            raise TransformError('a cloud has an empty frame_id')
        if target == source:
            return np.eye(4)
        up, down = self._chain(source), self._chain(target)
        common = next((f for f in up if f in down), None)
        if common is None:
            known = ', '.join(sorted(self.frames)) or 'none'
            raise TransformError(
                f'frame {source} cannot be resolved to {target} (tf frames: {known})'
            )
        to_common = np.eye(4)
        for child in up[: up.index(common)]:
            to_common = self._link(child, stamp) @ to_common
        target_to_common = np.eye(4)
        for child in down[: down.index(common)]:
            target_to_common = self._link(child, stamp) @ target_to_common
        return np.linalg.inv(target_to_common) @ to_common


def apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (n, 3) moved by a 4x4 matrix."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]
