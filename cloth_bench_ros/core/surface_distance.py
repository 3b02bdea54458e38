"""
The one point-to-surface distance: from points to a triangle mesh (the cloth's surface), exact.

For each point p, min over the points x of the mesh's triangles of ||p - x|| in L1 (the paper's
norm, the default) or L2. Exact, not sampled: a triangle's minimum is found in closed form. The
distance from p to the triangle's plane is |n . (p - a)| / max_k |n_k| in L1 (dual norm of L1 is
L-infinity), |n . (p - a)| / ||n||_2 in L2, reached by moving along one axis (L1) or along n (L2);
if that point of the plane lies inside the triangle it is the answer, otherwise the minimum lies
on the boundary (the norm is convex, so a minimum inside the triangle would be the plane's), and
an edge's minimum in L1 is at one of its ends or where it crosses a plane x_k = p_k (the sum of
absolute values is piecewise linear along the edge), in L2 at the clamped projection.

The triangles are bucketed once per mesh on a uniform grid (each in every cell its bounding box
overlaps); each point searches the cells in growing shells around its own, skipping cells and
triangles whose distance bound already exceeds the best found (as core/nearest.py does for
points), starting from the triangle nearest to the previous point (real frames arrive in raster
order, neighbours share a triangle). `TriangleMesh.farthest`: the largest distance, exact.
"""

from __future__ import annotations

from functools import lru_cache

from cloth_bench_ros.core.nearest import PointGrid
from numba import njit
import numpy as np

L1, L2 = 1, 2


@lru_cache(maxsize=16)
def grid_faces(nx: int, nz: int) -> np.ndarray:
    """Triangles of an nx x nz vertex grid (index j * nx + i), as core.scene.ClothGrid.faces."""
    j, i = np.meshgrid(np.arange(nz - 1), np.arange(nx - 1), indexing='ij')
    a = (j * nx + i).ravel()
    b, c, d = a + 1, a + nx, a + nx + 1
    faces = np.empty((2 * len(a), 3), dtype=np.int64)
    faces[0::2] = np.stack([a, c, b], axis=1)
    faces[1::2] = np.stack([b, c, d], axis=1)
    faces.setflags(write=False)
    return faces


class TriangleMesh:
    """A triangle mesh prepared once (edges, normals, boxes, a grid) for distance queries."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        v = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        f = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        # edges, normals, barycentric rows (a point a + w of the plane is at w . m1 along e1,
        # w . m2 along e2) and boxes, in one compiled pass: numpy's took longer than the search
        self.vertices = v
        self.a, self.e1, self.e2, self.n, self.m1, self.m2, self.lo, self.hi = _prepare(v, f)
        glo, ghi = self.lo.min(axis=0), self.hi.max(axis=0)
        extent = np.maximum(ghi - glo, 1e-9)
        # cells about half a triangle's size: a cell holds few triangles, a triangle few cells
        size = float(np.abs(self.e1).sum()) / len(f) / 2.0 if len(f) else 1.0
        cell = max(size, float(extent.max()) / 256.0, 1e-6)
        dims = np.minimum(np.floor(extent / cell).astype(np.int64) + 1, 256)
        self.glo, self.cell, self.dims = glo, cell, dims
        self.order, self.starts = _bucket_triangles(self.lo, self.hi, glo, cell, dims)

    def distances(self, points: np.ndarray, norm: int = L1) -> np.ndarray:
        """For each point, its distance to the nearest point of the mesh's surface (exact)."""
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(self.a) == 0:
            return np.full(len(p), np.inf)
        return _query(
            p, self.a, self.e1, self.e2, self.n, self.m1, self.m2, self.lo, self.hi,
            self.order, self.starts, self.glo, self.cell, self.dims, int(norm),
        )

    def farthest(
        self, grid: PointGrid, lower: float, on_surface: np.ndarray | None = None, norm: int = L1,
        measured: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> float:
        """
        Return max over the grid's points of their distance to the surface, exact.

        `lower`: a distance some points reach (0: none). A point is measured only if a bound can
        exceed the largest found: per grid cell (centre c), loosely, the anchors' (vertices,
        `on_surface`, `measured` points) known distance + their distance to c carried along the
        grid, then c's exact distance d_c, then d_c + ||p - c|| per point.
        """
        points = grid.points
        if len(self.a) == 0 or len(points) == 0:
            return float(np.inf) if len(points) else float(lower)
        # anchors of known distance (0 on the surface; `measured`: (points, their distances))
        parts = [np.asarray(x, dtype=np.float64).reshape(-1, 3)
                 for x in [self.vertices] + ([] if on_surface is None else [on_surface])]
        known = np.zeros(sum(len(x) for x in parts))
        if measured is not None:
            parts.append(np.asarray(measured[0], dtype=np.float64).reshape(-1, 3))
            known = np.concatenate([known, np.asarray(measured[1], dtype=np.float64)])
        at_centre = _carried(np.concatenate(parts), known, grid.lo, grid.cell, grid.dims)
        return float(_farthest(
            points, grid.order, grid.starts, grid.lo, grid.cell, grid.dims, at_centre,
            float(lower), self.a, self.e1, self.e2, self.n, self.m1, self.m2, self.lo, self.hi,
            self.order, self.starts, self.glo, self.cell, self.dims, int(norm),
        ))


def point_to_surface(
    points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, norm: int = L1
) -> np.ndarray:
    """Return each point's distance to the surface of the mesh (vertices, faces): L1 or L2."""
    return TriangleMesh(vertices, faces).distances(points, norm)


@njit(cache=True, nogil=True, inline='always')
def _cell_of(x, lo, inv, n):
    i = int((x - lo) * inv)
    return 0 if i < 0 else (n - 1 if i >= n else i)


@njit(cache=True, nogil=True)
def _cell_range(t, lo, hi, glo, inv, dims):
    """Return the cells (first and last along x, y, z) that triangle t's box overlaps."""
    return (
        _cell_of(lo[t, 0], glo[0], inv, dims[0]), _cell_of(hi[t, 0], glo[0], inv, dims[0]),
        _cell_of(lo[t, 1], glo[1], inv, dims[1]), _cell_of(hi[t, 1], glo[1], inv, dims[1]),
        _cell_of(lo[t, 2], glo[2], inv, dims[2]), _cell_of(hi[t, 2], glo[2], inv, dims[2]),
    )


@njit(cache=True, nogil=True)
def _bucket_triangles(lo, hi, glo, cell, dims):
    """Return triangle indices ordered by cell (each in every cell its box overlaps), starts."""
    inv = 1.0 / cell
    ncell = dims[0] * dims[1] * dims[2]
    starts = np.zeros(ncell + 1, dtype=np.int64)
    for t in range(lo.shape[0]):
        x0, x1, y0, y1, z0, z1 = _cell_range(t, lo, hi, glo, inv, dims)
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    starts[(iz * dims[1] + iy) * dims[0] + ix + 1] += 1
    for c in range(ncell):
        starts[c + 1] += starts[c]
    fill = starts[:-1].copy()
    order = np.empty(starts[ncell], dtype=np.int64)
    for t in range(lo.shape[0]):
        x0, x1, y0, y1, z0, z1 = _cell_range(t, lo, hi, glo, inv, dims)
        for iz in range(z0, z1 + 1):
            for iy in range(y0, y1 + 1):
                for ix in range(x0, x1 + 1):
                    c = (iz * dims[1] + iy) * dims[0] + ix
                    order[fill[c]] = t
                    fill[c] += 1
    return order, starts


@njit(cache=True, nogil=True, inline='always')
def _combine(gx, gy, gz, norm):
    if norm == 1:
        return gx + gy + gz
    return np.sqrt(gx * gx + gy * gy + gz * gz)


@njit(cache=True, nogil=True, inline='always')
def _gap(x, a, b):
    """Distance along one axis from x to the interval [a, b] (0 inside it)."""
    if x < a:
        return a - x
    return x - b if x > b else 0.0


# Numba inlines `inline='always'` functions in its own IR and types them again at every call site:
# _segment (9 calls in _triangle) and _nearest (in _query and twice in _cell_max) inlined took
# 280 s to compile on a fresh install against 20 s as plain calls, for a few % of their run time.
@njit(cache=True, nogil=True)
def _segment(px, py, pz, ax, ay, az, dx, dy, dz, norm):
    """Distance from p to the segment a + s d, s in [0, 1]."""
    if norm == 2:
        dd = dx * dx + dy * dy + dz * dz
        s = 0.0
        if dd > 0.0:
            s = ((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / dd
            s = min(max(s, 0.0), 1.0)
        rx, ry, rz = ax + s * dx - px, ay + s * dy - py, az + s * dz - pz
        return np.sqrt(rx * rx + ry * ry + rz * rz)
    # L1: piecewise linear in s; its minimum is at an end or at a breakpoint x_k = p_k
    best = abs(ax - px) + abs(ay - py) + abs(az - pz)
    end = abs(ax + dx - px) + abs(ay + dy - py) + abs(az + dz - pz)
    best = min(best, end)
    for k in range(3):
        d = dx if k == 0 else (dy if k == 1 else dz)
        if d == 0.0:
            continue
        q = px if k == 0 else (py if k == 1 else pz)
        o = ax if k == 0 else (ay if k == 1 else az)
        s = (q - o) / d
        if 0.0 < s < 1.0:
            v = abs(ax + s * dx - px) + abs(ay + s * dy - py) + abs(az + s * dz - pz)
            best = min(best, v)
    return best


@njit(cache=True, nogil=True, inline='always')
def _triangle(px, py, pz, t, a, e1, e2, n, m1, m2, norm, best):
    """
    Exact distance from p to triangle t, or a value >= best once it cannot be below best.

    The plane point x* lies outside the triangle past one edge's line (that edge holds the
    minimum: the segment from any point of the triangle to x* crosses that edge, and the norm
    does not grow along it) or past two (one of those two edges holds it).
    """
    ax, ay, az = a[t, 0], a[t, 1], a[t, 2]
    ux, uy, uz = e1[t, 0], e1[t, 1], e1[t, 2]
    vx, vy, vz = e2[t, 0], e2[t, 1], e2[t, 2]
    nx, ny, nz = n[t, 0], n[t, 1], n[t, 2]
    wx, wy, wz = px - ax, py - ay, pz - az
    s = nx * wx + ny * wy + nz * wz
    beta = wx * m1[t, 0] + wy * m1[t, 1] + wz * m1[t, 2]
    gamma = wx * m2[t, 0] + wy * m2[t, 1] + wz * m2[t, 2]
    if norm == 1:  # x* = p moved along the axis where the normal is largest
        anx, any_, anz = abs(nx), abs(ny), abs(nz)
        if anx >= any_ and anx >= anz:
            k, big = 0, nx
        elif any_ >= anz:
            k, big = 1, ny
        else:
            k, big = 2, nz
        if big == 0.0:  # a degenerate triangle: its edges
            return min(
                _segment(px, py, pz, ax, ay, az, ux, uy, uz, norm),
                _segment(px, py, pz, ax, ay, az, vx, vy, vz, norm),
                _segment(px, py, pz, ax + ux, ay + uy, az + uz, vx - ux, vy - uy, vz - uz, norm),
            )
        f = s / big
        dist = abs(f)
        beta -= f * m1[t, k]
        gamma -= f * m2[t, k]
    else:  # x* = p moved along the normal (m1, m2 are orthogonal to it)
        nn = nx * nx + ny * ny + nz * nz
        if nn == 0.0:
            return min(
                _segment(px, py, pz, ax, ay, az, ux, uy, uz, norm),
                _segment(px, py, pz, ax, ay, az, vx, vy, vz, norm),
                _segment(px, py, pz, ax + ux, ay + uy, az + uz, vx - ux, vy - uy, vz - uz, norm),
            )
        dist = abs(s) / np.sqrt(nn)
    if dist >= best:  # the plane is already farther
        return dist
    out_b, out_g, out_s = beta < 0.0, gamma < 0.0, beta + gamma > 1.0
    if not (out_b or out_g or out_s):
        return dist
    d = np.inf
    if out_g:  # past the edge a -> b
        d = _segment(px, py, pz, ax, ay, az, ux, uy, uz, norm)
    if out_b:  # past the edge a -> c
        d = min(d, _segment(px, py, pz, ax, ay, az, vx, vy, vz, norm))
    if out_s:  # past the edge b -> c
        bx, by, bz = ax + ux, ay + uy, az + uz
        d = min(d, _segment(px, py, pz, bx, by, bz, vx - ux, vy - uy, vz - uz, norm))
    return d


@njit(cache=True, nogil=True)
def _query(points, a, e1, e2, n, m1, m2, lo, hi, order, starts, glo, cell, dims, norm):
    seen = np.full(a.shape[0], -1, dtype=np.int64)
    out = np.empty(points.shape[0])
    last = 0
    for q in range(points.shape[0]):
        out[q], last = _nearest(
            points[q, 0], points[q, 1], points[q, 2], last, q, seen, a, e1, e2, n, m1, m2, lo,
            hi, order, starts, glo, cell, dims, norm,
        )
    return out


@njit(cache=True, nogil=True)
def _nearest(
    px, py, pz, last, stamp, seen, a, e1, e2, n, m1, m2, lo, hi, order, starts, glo, cell, dims,
    norm,
):
    """Return p's distance and nearest triangle from triangle `last` (seen[t] == stamp: done)."""
    inv = 1.0 / cell
    reach = max(dims[0], max(dims[1], dims[2]))
    slack = 1e-9 * cell
    # the previous point's nearest triangle first: a close bound from the start
    best = _triangle(px, py, pz, last, a, e1, e2, n, m1, m2, norm, np.inf)
    seen[last] = stamp
    best_t = last
    cx = _cell_of(px, glo[0], inv, dims[0])
    cy = _cell_of(py, glo[1], inv, dims[1])
    cz = _cell_of(pz, glo[2], inv, dims[2])
    # outside the grid's box, every cell of shell r is at least `off` (the distance to the
    # box) combined with r - 1 cells away: far points stop after a few shells
    ox = _gap(px, glo[0], glo[0] + cell * dims[0])
    oy = _gap(py, glo[1], glo[1] + cell * dims[1])
    oz = _gap(pz, glo[2], glo[2] + cell * dims[2])
    for r in range(reach + 1):
        shell = max(r - 1, 0) * cell
        if norm == 1:
            bound = ox + oy + oz + shell
        else:
            bound = np.sqrt(ox * ox + oy * oy + oz * oz + shell * shell)
        if bound > best + slack:  # nothing in this shell or beyond can be closer
            break
        for iz in range(max(cz - r, 0), min(cz + r, dims[2] - 1) + 1):
            z0 = glo[2] + iz * cell
            gz = _gap(pz, z0, z0 + cell)
            if gz > best + slack:
                continue
            for iy in range(max(cy - r, 0), min(cy + r, dims[1] - 1) + 1):
                y0 = glo[1] + iy * cell
                gy = _gap(py, y0, y0 + cell)
                if _combine(0.0, gy, gz, norm) > best + slack:
                    continue
                on_face = abs(iz - cz) == r or abs(iy - cy) == r
                step = 1 if on_face else 2 * r
                ix = max(cx - r, 0) if on_face else cx - r
                while ix <= min(cx + r, dims[0] - 1):
                    x0 = glo[0] + ix * cell
                    gap = _combine(_gap(px, x0, x0 + cell), gy, gz, norm)
                    if ix >= 0 and gap <= best + slack:
                        c = (iz * dims[1] + iy) * dims[0] + ix
                        for j in range(starts[c], starts[c + 1]):
                            t = order[j]
                            if seen[t] == stamp:
                                continue
                            seen[t] = stamp
                            bound = _combine(
                                _gap(px, lo[t, 0], hi[t, 0]),
                                _gap(py, lo[t, 1], hi[t, 1]),
                                _gap(pz, lo[t, 2], hi[t, 2]),
                                norm,
                            )
                            if bound >= best:
                                continue
                            d = _triangle(px, py, pz, t, a, e1, e2, n, m1, m2, norm, best)
                            if d < best:
                                best, best_t = d, t
                    ix += step
    return best, best_t


@njit(cache=True, nogil=True)
def _prepare(v, f):
    """Return each triangle's a, e1 = b - a, e2 = c - a, normal, barycentric rows, box."""
    m = f.shape[0]
    a, e1, e2 = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    n, m1, m2 = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    lo, hi = np.empty((m, 3)), np.empty((m, 3))
    for t in range(m):
        for k in range(3):
            a[t, k] = v[f[t, 0], k]
            e1[t, k] = v[f[t, 1], k] - a[t, k]
            e2[t, k] = v[f[t, 2], k] - a[t, k]
            lo[t, k] = min(a[t, k], v[f[t, 1], k], v[f[t, 2], k])
            hi[t, k] = max(a[t, k], v[f[t, 1], k], v[f[t, 2], k])
        _cross(e1[t], e2[t], 1.0, n[t])
        nn = n[t, 0] * n[t, 0] + n[t, 1] * n[t, 1] + n[t, 2] * n[t, 2]
        scale = 1.0 / nn if nn > 0.0 else 0.0
        _cross(e2[t], n[t], scale, m1[t])
        _cross(n[t], e1[t], scale, m2[t])
    return a, e1, e2, n, m1, m2, lo, hi


@njit(cache=True, nogil=True)
def _cross(u, w, scale, out):  # out = scale (u x w), no array allocated per triangle
    out[0] = (u[1] * w[2] - u[2] * w[1]) * scale
    out[1] = (u[2] * w[0] - u[0] * w[2]) * scale
    out[2] = (u[0] * w[1] - u[1] * w[0]) * scale


@njit(cache=True, nogil=True)
def _centre(c, lo, cell, dims):
    i, j, k = c % dims[0], (c // dims[0]) % dims[1], c // (dims[0] * dims[1])
    return lo[0] + (i + 0.5) * cell, lo[1] + (j + 0.5) * cell, lo[2] + (k + 0.5) * cell


@njit(cache=True, nogil=True)
def _carried(anchors, known, lo, cell, dims):
    """
    Return an upper bound of each cell centre's distance to the surface (triangle inequality).

    min over cells c' of (known[k] + anchor k's distance to the centre of c' where it lies) +
    ||centre(c) - centre(c')||_1: an L1 distance transform, one pass each way along each axis.
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    inv = 1.0 / cell
    f = np.full(nx * ny * nz, np.inf)
    for k in range(anchors.shape[0]):
        ax, ay, az = anchors[k, 0], anchors[k, 1], anchors[k, 2]
        c = (_cell_of(az, lo[2], inv, nz) * ny + _cell_of(ay, lo[1], inv, ny)) * nx
        c += _cell_of(ax, lo[0], inv, nx)
        x, y, z = _centre(c, lo, cell, dims)
        f[c] = min(f[c], known[k] + abs(ax - x) + abs(ay - y) + abs(az - z))
    for stride, n in ((1, nx), (nx, ny), (nx * ny, nz)):  # each axis: its lines of n cells
        for outer in range(0, nx * ny * nz, stride * n):
            for first in range(outer, outer + stride):
                for c in range(first + stride, first + n * stride, stride):
                    f[c] = min(f[c], f[c - stride] + cell)
                for c in range(first + (n - 2) * stride, first - 1, -stride):
                    f[c] = min(f[c], f[c + stride] + cell)
    return f


@njit(cache=True, nogil=True)
def _farthest(
    points, porder, pstarts, plo, pcell, pdims, at_centre, lower,
    a, e1, e2, n, m1, m2, lo, hi, order, starts, glo, cell, dims, norm,
):
    """
    Return max(lower, every point's distance to the surface), measuring few of them exactly.

    The cells whose bound (at_centre + half a diagonal) can exceed the largest distance found,
    highest bound first: the largest distance is found early and excludes most of the rest.
    """
    half = _combine(0.5 * pcell, 0.5 * pcell, 0.5 * pcell, norm) * (1.0 + 1e-9)
    cells = np.flatnonzero(
        (pstarts[1:] > pstarts[:-1]) & (at_centre + half > lower - 1e-9 * (abs(lower) + pcell))
    )
    bounds = at_centre[cells] + half
    seen = np.full(a.shape[0], -1, dtype=np.int64)
    state = np.array([lower, 0.0, 0.0])  # the largest distance, the last triangle, the stamp
    for i in np.argsort(-bounds):
        if bounds[i] <= state[0] - 1e-9 * (abs(state[0]) + pcell):
            break  # this cell and the rest cannot exceed the largest distance found
        _cell_max(cells[i], bounds[i], state, seen, points, porder, pstarts, plo, pcell, pdims,
                  half, a, e1, e2, n, m1, m2, lo, hi, order, starts, glo, cell, dims, norm)
    return state[0]


@njit(cache=True, nogil=True)
def _cell_max(
    c, bound, state, seen, points, porder, pstarts, plo, pcell, pdims, half,
    a, e1, e2, n, m1, m2, lo, hi, order, starts, glo, cell, dims, norm,
):
    """Raise state[0] to the largest distance of cell c's points where its bound can exceed it."""
    floor = state[0] - 1e-9 * (abs(state[0]) + pcell)  # bounds are computed: measure what's close
    if bound <= floor:
        return
    last, stamp = int(state[1]), int(state[2])
    cx, cy, cz = _centre(c, plo, pcell, pdims)
    dc, last = _nearest(cx, cy, cz, last, stamp, seen, a, e1, e2, n, m1, m2, lo, hi, order,
                        starts, glo, cell, dims, norm)
    stamp += 1
    if dc + half > floor:
        for j in range(pstarts[c], pstarts[c + 1]):
            q = porder[j]
            px, py, pz = points[q, 0], points[q, 1], points[q, 2]
            if dc + _combine(abs(px - cx), abs(py - cy), abs(pz - cz), norm) <= floor:
                continue
            d, last = _nearest(px, py, pz, last, stamp, seen, a, e1, e2, n, m1, m2, lo, hi,
                               order, starts, glo, cell, dims, norm)
            stamp += 1
            if d > state[0]:
                state[0] = d
                floor = d - 1e-9 * (abs(d) + pcell)
    state[1], state[2] = last, stamp
