"""
The one cloud-cleaning pipeline (the paper's pre-processing, segmentation aside).

In order: drop non-finite points (organized clouds mark missing pixels with NaN), crop to a box
around the cloth's workspace, remove the table plane, statistical outlier removal (open3d), and
optional voxel down-sampling. `run`, `import` and `synth` all clean through `clean`; every step
counts what it removed in a `CleaningStats`, so the summary can say so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from cloth_bench_ros.core import scene
from cloth_bench_ros.options import OPTIONS
import numpy as np

WORKSPACE_MARGIN = 0.10  # m around the reach of the cloth
TABLE_PLANE_DISTANCE = 0.01  # m: points this close to the table's plane are removed with it


@dataclass(frozen=True)
class CleaningConfig:
    """What `clean` does; a box of None skips the crop, 0 neighbours skips outlier removal."""

    box_min: tuple[float, float, float] | None = None
    box_max: tuple[float, float, float] | None = None
    table_plane: bool = True  # remove the table's plane (RANSAC, near-horizontal, near the table)
    table_distance: float = TABLE_PLANE_DISTANCE  # m: points this close to the plane belong to it
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
    primitives: tuple[str, ...] = ('dynamic', 'quasi_static'),
    voxel: float = OPTIONS['voxel'].default,
) -> CleaningConfig:
    """Return the cleaning for the benchmark scene: the box of the primitives' gripper paths."""
    from cloth_bench_ros.core.trajectory import full_targets

    paths = [full_targets(p, 100.0) for p in primitives]
    lo, hi = workspace_box(np.concatenate([np.concatenate([t.left, t.right]) for t in paths]))
    return CleaningConfig(lo, hi, voxel=voxel)


def _remove_table(points: np.ndarray, distance: float) -> np.ndarray:
    """Keep-mask without the largest near-horizontal plane close to the known table height."""
    import open3d as o3d

    near = np.abs(points[:, 2] - scene.TABLE_TOP_Z) < 0.1
    if near.sum() < 50:
        return np.ones(len(points), dtype=bool)
    idx = np.nonzero(near)[0]
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[idx]))
    o3d.utility.random.seed(0)  # RANSAC: the same cloud gives the same plane
    (a, b, c, d), inliers = cloud.segment_plane(
        distance_threshold=distance, ransac_n=3, num_iterations=200
    )
    keep = np.ones(len(points), dtype=bool)
    if abs(c) < 0.95 or len(inliers) < 0.2 * len(idx):  # not the table: vertical or too small
        return keep
    plane_distance = np.abs(points @ np.array([a, b, c]) + d) / np.linalg.norm([a, b, c])
    keep[plane_distance <= distance] = False
    return keep


def remove_outliers(points: np.ndarray, neighbors: int, std_ratio: float) -> np.ndarray:
    """open3d statistical outlier removal: drop points whose mean neighbour distance is unusual."""
    import open3d as o3d

    if neighbors <= 0 or len(points) <= neighbors:
        return points
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, float)))
    _, keep = cloud.remove_statistical_outlier(nb_neighbors=neighbors, std_ratio=std_ratio)
    return np.asarray(points)[np.asarray(keep, dtype=np.int64)]


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
        import open3d as o3d

        n = len(pts)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        pts = np.asarray(cloud.voxel_down_sample(config.voxel).points)
        stats.voxel_merged += n - len(pts)
    stats.points_out += len(pts)
    return pts
