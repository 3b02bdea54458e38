"""
The task's episode set-up every engine starts from: grasped corners, seeded initial state.

The cloth starts at rest in its mesh shape with the grasped vertices at the grippers (each vertex
shifted by the blend of the two grasps' shifts by its `grasp_weights`: a grid's column, a mesh's
projection on the line between the grasps), then every vertex except the
grasped corners is displaced by i.i.d. normal noise of SEED_NOISE_STD per coordinate from
numpy.random.default_rng(seed): one seed always gives the same run, different seeds a spread.
Engines apply this displacement to their own state; they do not draw it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from cloth_bench_ros.core.cloth_mesh import Cloth

SEED_NOISE_STD = 0.0005  # m


def grasped_corners(grid: Cloth) -> list[int]:
    """Vertex indices of the grasped vertices, left then right (a grid's top row's ends)."""
    return [grid.left_corner, grid.right_corner]


def initial_displacement(
    grid: Cloth, seed: int, left: np.ndarray, right: np.ndarray
) -> np.ndarray:
    """
    Return per vertex (n, 3) the initial state minus the rest shape.

    The grasped corners are at `left` and `right`, every other vertex is also perturbed by the
    seeded noise.
    """
    rest = grid.vertices()
    corners = grasped_corners(grid)
    s = grid.grasp_weights()[:, None]
    offset = (1 - s) * (left - rest[corners[0]]) + s * (right - rest[corners[1]])
    noise = np.random.default_rng(seed).normal(0.0, SEED_NOISE_STD, rest.shape)
    noise[corners] = 0.0
    return offset + noise
