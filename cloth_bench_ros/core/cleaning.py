"""
The one cloud-cleaning pipeline (the paper's pre-processing, segmentation aside).

In order: drop non-finite points (organized clouds mark missing pixels with NaN), crop to a box
around the cloth's workspace, remove the table plane (RANSAC over near-horizontal planes near the
known table height), statistical outlier removal, and optional voxel down-sampling: numpy and
scipy's k-d tree, open3d's definitions (docs/own-recording.md says how close they come to open3d's
own). `run`, `import` and `synth` all clean through `clean`; every step counts what it removed in
a `CleaningStats`, so the summary can say so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.trajectory import full_targets, TaskLike
from cloth_bench_ros.options import OPTIONS
import numpy as np
from scipy.spatial import cKDTree

WORKSPACE_MARGIN = 0.10  # m around the reach of the cloth
TABLE_SEARCH = 0.1  # m: the plane is searched among the points this close to the table height
TABLE_MIN_NORMAL_Z = 0.95  # |n_z| of a table's unit normal: at most 18 degrees from horizontal
RANSAC_ITERATIONS = 200


@dataclass(frozen=True)
class CleaningConfig:
    """What `clean` does; a box of None skips the crop, 0 neighbours skips outlier removal."""

    box_min: tuple[float, float, float] | None = None
    box_max: tuple[float, float, float] | None = None
    table_plane: bool = True  # remove the table's plane (RANSAC, near-horizontal, near the table)
    table_distance: float = scene.TABLE_PLANE_DISTANCE  # m: points this close belong to the plane
    sor_neighbors: int = 20
    sor_std_ratio: float = 3.0  # gentle: a cloud cleaned once already keeps its edges
    voxel: float = OPTIONS['voxel'].default  # m; 0: no down-sampling


@dataclass
class CleaningStats:
    """Points seen and removed per step, summed over the frames cleaned."""

    frames: int = 0
    points_in: int = 0
    non_finite: int = 0
    outside_box: int = 0
    table_plane: int = 0
    outliers: int = 0
    voxel_merged: int = 0
    points_out: int = 0

    def as_dict(self) -> dict[str, int]:
        """Plain dict for the summary (counts of points)."""
        return asdict(self)


def workspace_box(
    gripper_positions: np.ndarray, margin: float = WORKSPACE_MARGIN
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """
    Return a box holding the cloth wherever the grippers (k, 3) take it, above the table.

    The cloth hangs at most its length from the grippers and swings at most that far sideways.
    """
    p = np.asarray(gripper_positions, dtype=float).reshape(-1, 3)
    reach = scene.CLOTH_LENGTH + margin
    lo = p.min(axis=0) - reach
    hi = p.max(axis=0) + reach
    lo[2] = max(lo[2], scene.TABLE_TOP_Z - margin)
    hi[2] = p[:, 2].max() + margin
    return (float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2]))


def scene_cleaning(
    primitives: tuple[TaskLike, ...] = ('dynamic', 'quasi_static'),
    voxel: float = OPTIONS['voxel'].default,
) -> CleaningConfig:
    """Return the cleaning for the benchmark scene: the box of the tasks' gripper paths."""
    paths = [full_targets(p, 100.0) for p in primitives]
    lo, hi = workspace_box(np.concatenate([np.concatenate([t.left, t.right]) for t in paths]))
    return CleaningConfig(lo, hi, voxel=voxel)


def _remove_table(points: np.ndarray, distance: float) -> np.ndarray:
    """Keep-mask without the largest near-horizontal plane close to the known table height."""
    near = np.abs(points[:, 2] - scene.TABLE_TOP_Z) < TABLE_SEARCH
    keep = np.ones(len(points), dtype=bool)
    if near.sum() < 50:
        return keep
    candidates = points[near]
    plane = _table_plane(candidates, distance)
    if plane is None:
        return keep
    normal, offset = plane
    inliers = np.abs(candidates @ normal + offset) <= distance
    if inliers.sum() < 0.2 * len(candidates):  # not the table: too small a part of what is there
        return keep
    keep[np.abs(points @ normal + offset) <= distance] = False
    return keep


def find_table_z(points: np.ndarray, below_z: float) -> float | None:
    """
    Return the height of the table top among points (n, 3) below `below_z`, or None.

    The plane the cleaning removes, searched without knowing its height: the near-horizontal
    plane with the most inliers among the points below `below_z`, a table only if it holds at
    least a fifth of them; its height is its inliers' median z.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1) & (points[:, 2] < below_z)]
    if len(points) < 50:
        return None
    plane = _table_plane(points, scene.TABLE_PLANE_DISTANCE)
    if plane is None:
        return None
    normal, offset = plane
    inliers = np.abs(points @ normal + offset) <= scene.TABLE_PLANE_DISTANCE
    if inliers.sum() < 0.2 * len(points):
        return None
    return float(np.median(points[inliers, 2]))


def _table_plane(points: np.ndarray, distance: float) -> tuple[np.ndarray, float] | None:
    """
    Return the unit normal and offset of the near-horizontal plane with the most inliers.

    RANSAC from fixed draws (the same cloud gives the same plane): RANSAC_ITERATIONS planes
    through three points, those steeper than a table's skipped (a cloth hanging near the table
    can have more points than the table but is no table), the best refit to its inliers by least
    squares, as open3d's `segment_plane` refits its best plane.
    """
    rng = np.random.default_rng(0)
    triples = points[rng.integers(0, len(points), (RANSAC_ITERATIONS, 3))]
    normals = np.cross(triples[:, 1] - triples[:, 0], triples[:, 2] - triples[:, 0])
    length = np.linalg.norm(normals, axis=1)
    flat = np.abs(normals[:, 2]) >= TABLE_MIN_NORMAL_Z * length
    flat &= length > 0
    if not flat.any():
        return None
    normals = normals[flat] / length[flat, None]
    offsets = -np.einsum('ij,ij->i', normals, triples[flat, 0])
    counts = np.zeros(len(normals), dtype=np.int64)
    for start in range(0, len(points), 16384):  # (points x planes) distances, a block at a time
        block = points[start:start + 16384] @ normals.T + offsets
        counts += np.count_nonzero(np.abs(block) <= distance, axis=0)
    best = int(np.argmax(counts))
    members = points[np.abs(points @ normals[best] + offsets[best]) <= distance]
    centre = members.mean(axis=0)
    normal = np.linalg.svd(members - centre, full_matrices=False)[2][-1]
    if abs(normal[2]) < TABLE_MIN_NORMAL_Z:  # the refit tilted away from horizontal
        return None
    return normal, float(-normal @ centre)


def remove_outliers(points: np.ndarray, neighbors: int, std_ratio: float) -> np.ndarray:
    """
    Statistical outlier removal: drop points whose mean neighbour distance is unusual.

    open3d's rule: a point's mean distance to its `neighbors` nearest points (itself among
    them) must be positive and below the mean of those distances plus `std_ratio` standard
    deviations (Bessel-corrected).
    """
    pts = np.asarray(points, dtype=np.float64)
    if neighbors <= 0 or len(pts) <= neighbors:
        return pts
    distances, _ = cKDTree(pts).query(pts, k=neighbors)
    mean = distances.mean(axis=1)
    positive = mean > 0
    cloud_mean = mean[positive].sum() / len(mean)
    std = np.sqrt(np.square(mean[positive] - cloud_mean).sum() / (len(mean) - 1))
    return pts[positive & (mean < cloud_mean + std_ratio * std)]


def voxel_down_sample(points: np.ndarray, voxel: float) -> np.ndarray:
    """Return the mean of the points in each occupied voxel (open3d's grid), in voxel order."""
    lowest = points.min(axis=0) - 0.5 * voxel
    index = np.floor((points - lowest) / voxel).astype(np.int64)
    _, cell, counts = np.unique(index, axis=0, return_inverse=True, return_counts=True)
    cell = cell.reshape(-1)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, cell, points)
    return sums / counts[:, None]


def clean(
    points: np.ndarray, config: CleaningConfig, stats: CleaningStats | None = None
) -> np.ndarray:
    """Return the cleaned (m, 3) float64 points of a cloud (any shape (..., 3), NaN allowed)."""
    stats = stats if stats is not None else CleaningStats()
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    stats.frames += 1
    stats.points_in += len(pts)
    finite = np.isfinite(pts).all(axis=1)
    stats.non_finite += int(len(pts) - finite.sum())
    pts = pts[finite]
    if config.box_min is not None and config.box_max is not None:
        inside = np.all((pts >= config.box_min) & (pts <= config.box_max), axis=1)
        stats.outside_box += int(len(pts) - inside.sum())
        pts = pts[inside]
    if config.table_plane and len(pts):
        keep = _remove_table(pts, config.table_distance)
        stats.table_plane += int(len(pts) - keep.sum())
        pts = pts[keep]
    n = len(pts)
    pts = remove_outliers(pts, config.sor_neighbors, config.sor_std_ratio)
    stats.outliers += n - len(pts)
    if config.voxel > 0 and len(pts):
        n = len(pts)
        pts = voxel_down_sample(pts, config.voxel)
        stats.voxel_merged += n - len(pts)
    stats.points_out += len(pts)
    return pts
