"""The exact point-to-surface distance against independent implementations."""

from cloth_bench_ros.core.nearest import PointGrid
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.surface_distance import (
    grid_faces,
    L1,
    L2,
    point_to_surface,
    TriangleMesh,
)
import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import cKDTree
import trimesh


def _wavy_mesh(nx: int = 7, nz: int = 9, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    grid = ClothGrid(nx, nz)
    vertices = grid.vertices() + rng.normal(scale=0.02, size=(nx * nz, 3))
    return vertices, grid_faces(nx, nz)


def _dense_samples(vertices: np.ndarray, faces: np.ndarray, per_edge: int) -> np.ndarray:
    """Every triangle sampled on a regular barycentric lattice (its corners and edges included)."""
    lattice = np.array(
        [(i, j) for i in range(per_edge + 1) for j in range(per_edge + 1 - i)], dtype=float
    ) / per_edge
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    s, t = lattice[None, :, :1], lattice[None, :, 1:]
    return (a[:, None] + s * (b - a)[:, None] + t * (c - a)[:, None]).reshape(-1, 3)


def test_grid_faces_are_the_cloth_grids_triangles():
    for nx, nz in ((2, 2), (11, 15), (4, 7)):
        assert np.array_equal(grid_faces(nx, nz), ClothGrid(nx, nz).faces())


def test_l1_distance_matches_a_kd_tree_on_dense_surface_samples():
    vertices, faces = _wavy_mesh()
    rng = np.random.default_rng(2)
    points = rng.uniform([-0.1, -0.1, 0.2], [0.6, 0.1, 1.1], size=(2000, 3))
    exact = point_to_surface(points, vertices, faces, L1)
    per_edge = 60
    sampled = cKDTree(_dense_samples(vertices, faces, per_edge)).query(points, p=1)[0]
    # the samples lie on the surface: the exact distance is never larger ...
    assert np.all(exact <= sampled + 1e-12)
    # ... and at most the L1 reach of a lattice cell smaller (edges <= ~0.12 m in L1 here)
    edge_l1 = max(np.abs(vertices[faces[:, i]] - vertices[faces[:, j]]).sum(axis=1).max()
                  for i, j in ((0, 1), (1, 2), (0, 2)))
    assert np.all(sampled - exact <= edge_l1 / per_edge)
    assert np.mean(sampled - exact) < 1e-3


def test_l1_distance_matches_a_linear_program_per_triangle():
    """Equal the LP min ||p - (a + s e1 + t e2)||_1, s, t >= 0, s + t <= 1 (HiGHS)."""
    vertices, faces = _wavy_mesh(4, 4, seed=3)
    rng = np.random.default_rng(4)
    points = rng.uniform([-0.1, -0.1, 0.6], [0.6, 0.1, 1.1], size=(12, 3))
    exact = point_to_surface(points, vertices, faces, L1)
    for p, d in zip(points, exact):
        best = np.inf
        for f in faces:
            a = vertices[f[0]]
            e1, e2 = vertices[f[1]] - a, vertices[f[2]] - a
            # variables s, t, u (3): u_k >= |a_k + s e1_k + t e2_k - p_k|
            c = [0, 0, 1, 1, 1]
            rows, rhs = [], []
            for k in range(3):
                unit = [0, 0, 0]
                unit[k] = -1
                rows.append([e1[k], e2[k], *unit])
                rhs.append(p[k] - a[k])
                rows.append([-e1[k], -e2[k], *unit])
                rhs.append(a[k] - p[k])
            rows.append([1, 1, 0, 0, 0])
            rhs.append(1)
            res = linprog(c, A_ub=rows, b_ub=rhs, bounds=[(0, None)] * 5, method='highs')
            best = min(best, res.fun)
        assert d == pytest.approx(best, abs=1e-9)


def test_l2_distance_matches_trimesh():
    vertices, faces = _wavy_mesh()
    rng = np.random.default_rng(5)
    points = rng.uniform([-0.1, -0.1, 0.2], [0.6, 0.1, 1.1], size=(300, 3))
    exact = point_to_surface(points, vertices, faces, L2)
    triangles = vertices[faces]
    expected = np.empty(len(points))
    for i, p in enumerate(points):  # trimesh's closest point on every triangle, brute force
        closest = trimesh.triangles.closest_point(triangles, np.repeat(p[None], len(faces), 0))
        expected[i] = np.linalg.norm(closest - p, axis=1).min()
    np.testing.assert_allclose(exact, expected, rtol=0, atol=1e-12)


def test_points_on_the_surface_and_far_from_it():
    vertices, faces = _wavy_mesh()
    on = _dense_samples(vertices, faces, 5)
    assert np.max(point_to_surface(on, vertices, faces)) < 1e-12
    far = np.array([[10.0, 0.0, 0.0], [-3.0, 2.0, 1.0]])
    sampled = cKDTree(_dense_samples(vertices, faces, 40)).query(far, p=1)[0]
    exact = point_to_surface(far, vertices, faces)
    assert np.all(exact <= sampled) and np.all(sampled - exact < 0.01)


def test_degenerate_triangles_are_measured_by_their_edges():
    vertices = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])  # three collinear points
    faces = np.array([[0, 1, 2]])
    d = point_to_surface(np.array([[0.5, 0.2, 0.1], [3.0, 0, 0]]), vertices, faces)
    np.testing.assert_allclose(d, [0.3, 1.0])


@pytest.mark.parametrize('norm', [L1, L2])
def test_the_farthest_point_is_the_exact_maximum_over_every_point(norm):
    """HD from a cloud to the surface, pruned by bounds, equals the max of every exact distance."""
    vertices, faces = _wavy_mesh()
    mesh = TriangleMesh(vertices, faces)
    rng = np.random.default_rng(7)
    sheet = rng.uniform([0.0, -0.01, 0.3], [0.5, 0.01, 1.0], size=(20000, 3))
    stray = np.array([[0.25, 0.12, 0.65], [0.7, 0.0, 0.5]])  # two points far off the cloth
    for points in (sheet, np.concatenate([sheet[:9000], stray, sheet[9000:]])):
        exact = mesh.distances(points, norm)
        grid = PointGrid(points)
        on_surface = _dense_samples(vertices, faces, 3)
        for lower in (0.0, float(exact[::50].max()), float(exact.max())):
            for anchors in (None, on_surface):
                assert mesh.farthest(grid, lower, anchors, norm) == exact.max()
