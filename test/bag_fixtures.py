"""Small real MCAP bags made on the spot, shared by the tests and conftest.py's fixtures."""

from __future__ import annotations

from pathlib import Path

from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.data import BagWriter, TrialInfo
import numpy as np

FPS = 30.0


def write_hanging_cloth_bag(
    path: Path,
    frames: int = 132,
    points_per_side: int = 25,
    seed: int = 0,
    primitive: str = 'dynamic',
    change_of_phase_frame: int | None = 99,
) -> Path:
    """Return a bag of a flat cloth hanging at rest (0.5 x 0.7 m), 1 mm noise, at 30 Hz."""
    rng = np.random.default_rng(seed)
    grid = ClothGrid(points_per_side, points_per_side).vertices()
    trial = TrialInfo(
        cloth='towel',
        trial=0,
        primitive=primitive,
        change_of_phase_frame=change_of_phase_frame,
        source='test fixture: flat hanging cloth',
    )
    with BagWriter(path, trial=trial) as bag:
        for k in range(frames):
            points = grid + rng.normal(scale=0.001, size=grid.shape)
            bag.write_cloud('/cloth_bench/real/cloud', round(k * 1e9 / FPS), points)
    return path
