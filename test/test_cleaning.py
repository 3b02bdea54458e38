"""The cleaning (numpy and scipy) against open3d's own steps, on camera-like frames."""

from __future__ import annotations

import subprocess
import sys

from camera_recording import scene_clutter
from cloth_bench_ros.core import cleaning
from cloth_bench_ros.core.scene import TABLE_TOP_Z
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.paths import bundled_bag
import numpy as np
import pytest


def _camera_frames(every: int = 10) -> list[np.ndarray]:
    """Every `every`-th frame of the bundled fling with 2 mm noise, the table and background."""
    rng = np.random.default_rng(3)
    clouds = [c for k, (_, c) in enumerate(BagReader(bundled_bag('towel', 'dynamic')).clouds())
              if k % every == 0]
    return [np.concatenate([c + rng.normal(0, 0.002, c.shape), scene_clutter(rng)])
            for c in clouds]


def _in_box(points: np.ndarray) -> np.ndarray:
    config = cleaning.scene_cleaning()
    return points[np.all((points >= config.box_min) & (points <= config.box_max), axis=1)]


def test_outlier_removal_and_voxels_are_open3ds():
    o3d = pytest.importorskip('open3d')
    for points in _camera_frames():
        points = _in_box(points)
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        _, kept = cloud.remove_statistical_outlier(nb_neighbors=20, std_ratio=3.0)
        ours = cleaning.remove_outliers(points, 20, 3.0)
        assert np.array_equal(ours, points[np.sort(np.asarray(kept, dtype=np.int64))])
        theirs = np.asarray(cloud.voxel_down_sample(0.01).points)
        mine = cleaning.voxel_down_sample(points, 0.01)
        assert np.array_equal(_ordered(mine), _ordered(theirs))  # open3d's is its hash map's


def _ordered(points: np.ndarray) -> np.ndarray:
    return points[np.lexsort(points.T[::-1])]


def test_the_table_goes_where_open3d_finds_it_and_where_a_cloth_hides_it():
    o3d = pytest.importorskip('open3d')
    found_by_both = 0
    for points in _camera_frames():
        points = _in_box(points)
        ours = ~cleaning._remove_table(points, 0.01)
        table = np.abs(points[:, 2] - TABLE_TOP_Z) < 0.004  # the clutter's table, 1 mm noise
        assert ours[table].all()  # every table point removed
        near = np.abs(points[:, 2] - TABLE_TOP_Z) < cleaning.TABLE_SEARCH
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points[near]))
        o3d.utility.random.seed(0)
        (_, _, c, _), inliers = cloud.segment_plane(0.01, 3, 200)
        if abs(c) >= cleaning.TABLE_MIN_NORMAL_Z:  # open3d's best plane is the table too
            theirs = np.zeros(len(points), dtype=bool)
            theirs[np.nonzero(near)[0][inliers]] = True
            assert np.count_nonzero(ours != theirs) <= 0.02 * np.count_nonzero(theirs)
            found_by_both += 1
    # the frames after landing, where open3d's best plane is the lying cloth's slope, remain
    assert found_by_both >= 10


def test_the_cleaning_runs_without_open3d():
    code = (
        'import sys; sys.modules["open3d"] = None\n'
        'from test_cleaning import _camera_frames\n'
        'from cloth_bench_ros.core import cleaning\n'
        'stats = cleaning.CleaningStats()\n'
        'config = cleaning.scene_cleaning(voxel=0.005)\n'
        'for points in _camera_frames(40):\n'
        '    cleaning.clean(points, config, stats)\n'
        'assert stats.table_plane and stats.outliers and stats.voxel_merged, stats\n'
    )
    here = str(__import__('pathlib').Path(__file__).parent)
    done = subprocess.run([sys.executable, '-c', code], cwd=here, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
