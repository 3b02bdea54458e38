"""
Sim-to-real metrics (docs/benchmark.md, section 3).

One-sided L1 Chamfer and Hausdorff distances from the simulated vertices V to the real cloud P
(the nearest neighbour is taken under the L1 norm too), the stability L_s of a sequence of
simulated frames, and step-latency statistics.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib

from cloth_bench_ros.core.nearest import PointGrid
import numpy as np


def _points(name: str, a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f'{name} must have shape (n, 3), got {a.shape}')
    if len(a) == 0:
        raise ValueError(f'{name} is empty')
    if not np.isfinite(a).all():
        raise ValueError(f'{name} holds non-finite values')
    return a


class RealCloud:
    """A real point cloud P indexed once (a uniform grid) to score several meshes on it."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = _points('P', points)
        self._grid = PointGrid(self.points)

    @property
    def grid(self) -> PointGrid:
        """Return the uniform grid the points are bucketed on, for other searches over them."""
        return self._grid

    @classmethod
    def of(cls, points: np.ndarray) -> 'RealCloud':
        """RealCloud(points), from the process's tree cache when `keep_trees` enabled it."""
        if _TREE_CACHE_LIMIT <= 0:
            return cls(points)
        points = np.ascontiguousarray(points, dtype=float)
        key = (points.shape, hashlib.blake2b(points.tobytes(), digest_size=16).digest())
        global _TREE_CACHE_POINTS
        cloud = _TREE_CACHE.pop(key, None)
        if cloud is None:
            cloud = cls(points)
            _TREE_CACHE_POINTS += len(cloud.points)
        _TREE_CACHE[key] = cloud  # most recently used last
        while _TREE_CACHE_POINTS > _TREE_CACHE_LIMIT and len(_TREE_CACHE) > 1:
            _TREE_CACHE_POINTS -= len(_TREE_CACHE.pop(next(iter(_TREE_CACHE))).points)
        return cloud

    def nearest_l1(self, vertices: np.ndarray) -> np.ndarray:
        """For each vertex v, min over p of ||v - p||_1 (exact: the grid is searched in L1)."""
        return self._grid.nearest_l1(_points('V', vertices))

    def chamfer_hausdorff(self, vertices: np.ndarray) -> tuple[float, float]:
        """(CD, HD) of the vertices against this cloud."""
        d = self.nearest_l1(vertices)
        return float(d.mean()), float(d.max())


_TREE_CACHE: dict = {}
_TREE_CACHE_POINTS = 0
_TREE_CACHE_LIMIT = 0


def keep_trees(max_points: int) -> None:
    """
    Keep the k-d trees of the clouds scored in this process (up to `max_points` points).

    A study's worker that scores the same bag again finds its trees built (0 turns the cache off).
    """
    global _TREE_CACHE_LIMIT, _TREE_CACHE_POINTS
    _TREE_CACHE_LIMIT = int(max_points)
    _TREE_CACHE.clear()
    _TREE_CACHE_POINTS = 0


def chamfer_l1(V: np.ndarray, P: np.ndarray) -> float:
    """CD(V, P) = mean over v in V of min over p in P of ||v - p||_1."""
    return float(RealCloud(P).nearest_l1(V).mean())


def hausdorff_l1(V: np.ndarray, P: np.ndarray) -> float:
    """HD(V, P) = max over v in V of min over p in P of ||v - p||_1."""
    return float(RealCloud(P).nearest_l1(V).max())


def stability(frames: np.ndarray) -> float:
    """Return L_s of frames (N, n, 3): the mean distance of each frame to its 3-frame average."""
    frames = np.asarray(frames, dtype=np.float64)
    if frames.ndim != 3 or frames.shape[2] != 3:
        raise ValueError(f'frames must have shape (N, n, 3), got {frames.shape}')
    acc = StabilityAccumulator()
    for frame in frames:
        acc.add(frame)
    return acc.value


class StabilityAccumulator:
    """
    L_s computed online: bounded memory, the same number as `stability` on the whole sequence.

    Frames are kept by reference (the caller must not change them afterwards) and reduced in
    blocks of `BLOCK`: one vectorised pass per block instead of six array operations per frame,
    with each frame's mean and the running sum taken in the formula's own order.
    """

    BLOCK = 64

    def __init__(self) -> None:
        self._frames: list[np.ndarray] = []  # the last two reduced frames, then the pending ones
        self._sum = 0.0
        self.count = 0

    def add(self, frame: np.ndarray) -> None:
        self._frames.append(np.asarray(frame, dtype=np.float64))
        self.count += 1
        if len(self._frames) >= self.BLOCK + 2:
            self._reduce()

    def _reduce(self) -> None:
        """Add the terms of the pending frames whose two neighbours are known."""
        frames = self._frames
        if len(frames) < 3:
            return
        if len({f.shape for f in frames}) != 1:
            raise ValueError('stability: every frame must have the same shape')
        stack = np.stack(frames)
        filtered = stack[:-2] + stack[1:-1]
        filtered += stack[2:]
        filtered /= 3.0
        filtered -= stack[1:-1]
        np.abs(filtered, out=filtered)
        rows = filtered.reshape(len(filtered), -1)
        means = np.add.reduce(rows, axis=1) / rows.shape[1]
        total = self._sum
        for m in means.tolist():  # one by one, in order, as a running sum
            total += m
        self._sum = total
        self._frames = frames[-2:]

    @property
    def value(self) -> float:
        self._reduce()
        return self._sum / self.count if self.count else float('nan')


@dataclass(frozen=True)
class LatencyStats:
    """Step-time statistics in seconds."""

    count: int
    mean: float
    p50: float
    p99: float
    max: float  # noqa: A003  (a statistic's name, as in the summary's keys)

    def as_dict(self) -> dict[str, float]:
        return {
            'count': self.count,
            'mean': self.mean,
            'p50': self.p50,
            'p99': self.p99,
            'max': self.max,
        }


def latency_stats(samples: np.ndarray) -> LatencyStats:
    """Mean, median, 99th percentile and maximum of step times (NaN when there are none)."""
    s = np.asarray(samples, dtype=np.float64)
    if s.size == 0:
        nan = float('nan')
        return LatencyStats(0, nan, nan, nan, nan)
    return LatencyStats(
        int(s.size),
        float(s.mean()),
        float(np.percentile(s, 50)),
        float(np.percentile(s, 99)),
        float(s.max()),
    )
