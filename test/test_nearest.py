"""The grid search of core/nearest.py equals brute force, on ordinary and adversarial clouds."""

from __future__ import annotations

from cloth_bench_ros.core.metrics import chamfer_l1, hausdorff_l1, RealCloud
from cloth_bench_ros.core.nearest import PointGrid
import numpy as np
import pytest


def brute(V: np.ndarray, P: np.ndarray) -> np.ndarray:
    return np.abs(V[:, None, :] - P[None, :, :]).sum(axis=2).min(axis=1)


def clouds(case: str, rng) -> tuple[np.ndarray, np.ndarray]:
    V = rng.uniform(-0.3, 0.8, (120, 3))
    if case == 'random':
        return V, rng.normal(0.2, 0.2, (3000, 3))
    if case == 'duplicates':
        base = rng.normal(0.2, 0.2, (50, 3))
        return V, np.repeat(base, 40, axis=0)
    if case == 'flat':  # every point on the table plane: one cell thick in z
        return V, np.column_stack(
            [rng.uniform(0, 0.5, 2000), rng.uniform(-0.3, 0.3, 2000), np.full(2000, 0.195)]
        )
    if case == 'line':
        return V, np.column_stack([np.linspace(0, 1, 500), np.zeros(500), np.zeros(500)])
    if case == 'single_point':
        return V, np.array([[0.1, 0.2, 0.3]])
    if case == 'one_far_outlier':  # stretches the grid: most cells empty
        P = rng.normal(0.2, 0.05, (2000, 3))
        P[0] = (40.0, -25.0, 13.0)
        return V, P
    if case == 'vertices_far_outside':
        return rng.uniform(5, 9, (60, 3)) * rng.choice([-1, 1], (60, 3)), rng.normal(
            0.2, 0.2, (2000, 3)
        )
    if case == 'ties':  # integer lattice: many points at the same L1 distance
        g = np.arange(-3, 4, dtype=float)
        P = np.array(np.meshgrid(g, g, g)).reshape(3, -1).T * 0.05
        return np.round(V * 20) / 20 + 0.025, P
    if case == 'offset':  # far from the origin, as points in a robot's base frame can be
        P = rng.normal(0.2, 0.2, (2000, 3)) + 1e4
        return V + 1e4, P
    raise ValueError(case)


CASES = [
    'random',
    'duplicates',
    'flat',
    'line',
    'single_point',
    'one_far_outlier',
    'vertices_far_outside',
    'ties',
    'offset',
]


@pytest.mark.parametrize('case', CASES)
def test_grid_equals_brute_force_exactly(case):
    V, P = clouds(case, np.random.default_rng(CASES.index(case)))
    np.testing.assert_array_equal(PointGrid(P).nearest_l1(V), brute(V, P))


def test_one_grid_serves_many_meshes_and_the_metrics():
    rng = np.random.default_rng(7)
    P = rng.normal(0.2, 0.2, (5000, 3))
    cloud = RealCloud(P)
    for _ in range(3):
        V = rng.uniform(-0.5, 1.0, (200, 3))
        d = brute(V, P)
        assert cloud.chamfer_hausdorff(V) == (float(d.mean()), float(d.max()))
        assert chamfer_l1(V, P) == float(d.mean()) and hausdorff_l1(V, P) == float(d.max())


def test_float32_input_is_scored_in_float64():
    rng = np.random.default_rng(8)
    P = rng.normal(0.2, 0.2, (1000, 3)).astype(np.float32)
    V = rng.uniform(-0.5, 1.0, (50, 3))
    np.testing.assert_array_equal(PointGrid(P).nearest_l1(V), brute(V, P.astype(np.float64)))
