"""
The task's episode set-up every engine starts from: grasped corners, seeded initial state.

The cloth starts at rest in its grid shape with the grasped corners at the grippers (each column
of the grid shifted by the linear blend of the two corners' shifts), then every vertex except the
grasped corners is displaced by i.i.d. normal noise of SEED_NOISE_STD per coordinate from
numpy.random.default_rng(seed): one seed always gives the same run, different seeds a spread.
Engines apply this displacement to their own state; they do not draw it.
"""

from __future__ import annotations

from cloth_bench_ros.core.scene import ClothGrid
import numpy as np

SEED_NOISE_STD = 0.0005  # m


def grasped_corners(grid: ClothGrid) -> list[int]:
    """Vertex indices of the grasped corners, left then right: the ends of the grid's top row."""
    return [grid.left_corner, grid.right_corner]


def initial_displacement(
    grid: ClothGrid, seed: int, left: np.ndarray, right: np.ndarray
) -> np.ndarray:
    """
    Return per vertex (n, 3) the initial state minus the rest shape.

    The grasped corners are at `left` and `right`, every other vertex is also perturbed by the
    seeded noise.
    """
    rest = grid.vertices()
    corners = grasped_corners(grid)
    s = np.linspace(0.0, 1.0, grid.nx)[:, None]
    column_shift = (1 - s) * (left - rest[corners[0]]) + s * (right - rest[corners[1]])
    offset = np.tile(column_shift, (grid.nz, 1))
    noise = np.random.default_rng(seed).normal(0.0, SEED_NOISE_STD, rest.shape)
    noise[corners] = 0.0
    return offset + noise
