"""
Exact L1 nearest-neighbour distances from a few query points to a large cloud, on a uniform grid.

The evaluator asks, for every vertex of a simulated mesh (hundreds), the L1 distance to the
nearest point of a real frame (50,000 to 300,000 points). A k-d tree over the frame costs
O(n log n) to build for every frame; a grid costs O(n): the points are bucketed by cell with a
counting sort, and each vertex searches the cells around its own in growing shells, skipping every
cell whose L1 distance to the vertex already exceeds the best found, and stopping once no
unsearched cell can hold a closer point (every point of shell r lies at least (r - 1) cells away
in one coordinate, hence at least that far in L1, plus the vertex's distance to the grid's box).
The distance is |dx| + |dy| + |dz| summed in that order, as a brute force over all pairs computes
it.
"""

from __future__ import annotations

from numba import njit
import numpy as np

POINTS_PER_CELL = 16.0  # cells ~ points / 16 (measured best of 2, 8, 16, 32 on camera-like frames)


class PointGrid:
    """A cloud bucketed on a uniform grid once, queried for any number of vertex sets."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        lo, hi = _bounds(self.points)  # one pass; ndarray.min(axis=0) walks an (n, 3) array slowly
        extent = np.maximum(hi - lo, 1e-9)
        # a flat cloud (a sheet seen edge-on, a synthetic plane) sized as if 1/32 of its length
        # thick: else its near-zero volume makes the cells tiny and the grid mostly empty
        volume = np.prod(np.maximum(extent, float(extent.max()) / 32.0))
        cell = float(np.cbrt(volume * POINTS_PER_CELL / len(self.points)))
        cell = max(cell, float(extent.max()) / 1024.0)  # at most 1024 cells along an axis
        dims = np.minimum(np.floor(extent / cell).astype(np.int64) + 1, 1024)
        self.lo, self.cell, self.dims = lo, cell, dims
        self.order, self.starts = _bucket(self.points, lo, 1.0 / cell, dims)

    def nearest_l1(self, vertices: np.ndarray) -> np.ndarray:
        """For each vertex, min over the cloud of ||v - p||_1 (exact)."""
        queries = np.ascontiguousarray(vertices, dtype=np.float64)
        return _nearest(
            self.points, self.order, self.starts, self.lo, self.cell, self.dims, queries
        )


@njit(cache=True, nogil=True)
def _cell_of(x: float, lo: float, inv: float, n: int) -> int:
    i = int((x - lo) * inv)
    return 0 if i < 0 else (n - 1 if i >= n else i)


@njit(cache=True, nogil=True)
def _bounds(points):
    lo = np.empty(3)
    hi = np.empty(3)
    for a in range(3):  # one axis at a time: branch-free min/max the compiler vectorises
        low = high = points[0, a]
        for k in range(points.shape[0]):
            x = points[k, a]
            low = min(low, x)
            high = max(high, x)
        lo[a], hi[a] = low, high
    return lo, hi


@njit(cache=True, nogil=True)
def _bucket(points, lo, inv, dims):
    """Return the points' indices ordered by cell and each cell's start in that order."""
    n = points.shape[0]
    ncell = dims[0] * dims[1] * dims[2]
    ids = np.empty(n, dtype=np.int32)
    for k in range(n):
        ix = _cell_of(points[k, 0], lo[0], inv, dims[0])
        iy = _cell_of(points[k, 1], lo[1], inv, dims[1])
        iz = _cell_of(points[k, 2], lo[2], inv, dims[2])
        ids[k] = (iz * dims[1] + iy) * dims[0] + ix
    # Four interleaved counters: neighbouring points share a cell, and increments of one counter
    # in a row would wait for each other.
    partial = np.zeros((4, ncell + 1), dtype=np.int32)
    for k in range(n):
        partial[k & 3, ids[k] + 1] += 1
    starts = np.zeros(ncell + 1, dtype=np.int32)
    for c in range(ncell):
        starts[c + 1] = (
            starts[c]
            + partial[0, c + 1]
            + partial[1, c + 1]
            + partial[2, c + 1]
            + partial[3, c + 1]
        )
    fill = starts[:-1].copy()
    order = np.empty(n, dtype=np.int32)  # indices, not points: a quarter of the scattered bytes
    for k in range(n):
        c = ids[k]
        order[fill[c]] = k
        fill[c] += 1
    return order, starts


@njit(cache=True, nogil=True)
def _gap(x: float, lo: float, cell: float, i: int) -> float:
    """Distance along one axis from x to cell i's slab (0 inside it)."""
    a = lo + i * cell
    if x < a:
        return a - x
    b = a + cell
    return x - b if x > b else 0.0


@njit(cache=True, nogil=True)
def _nearest(points, order, starts, lo, cell, dims, queries):
    inv = 1.0 / cell
    out = np.empty(queries.shape[0])
    reach = max(dims[0], max(dims[1], dims[2]))
    slack = (
        1e-9 * cell
    )  # the cell bounds are computed, not exact: prune only what is clearly farther
    for q in range(queries.shape[0]):
        vx, vy, vz = queries[q, 0], queries[q, 1], queries[q, 2]
        cx = _cell_of(vx, lo[0], inv, dims[0])
        cy = _cell_of(vy, lo[1], inv, dims[1])
        cz = _cell_of(vz, lo[2], inv, dims[2])
        # A query outside the grid's box is `off` away from it in L1, and every point of shell r
        # (around the cell the query is clamped to) at least `off` + (r - 1) cells: a far query
        # (a cloth far from the cloud) stops after a few shells, not after off / cell of them.
        off = (
            _gap(vx, lo[0], cell * dims[0], 0)
            + _gap(vy, lo[1], cell * dims[1], 0)
            + _gap(vz, lo[2], cell * dims[2], 0)
        )
        best = np.inf
        for r in range(reach + 1):
            if off + (r - 1) * cell > best + slack:  # no point of this shell or beyond is closer
                break
            for iz in range(max(cz - r, 0), min(cz + r, dims[2] - 1) + 1):
                gz = _gap(vz, lo[2], cell, iz)
                if gz > best + slack:
                    continue
                for iy in range(max(cy - r, 0), min(cy + r, dims[1] - 1) + 1):
                    gyz = gz + _gap(vy, lo[1], cell, iy)
                    if gyz > best + slack:
                        continue
                    on_face = abs(iz - cz) == r or abs(iy - cy) == r
                    step = 1 if on_face else 2 * r  # inside the shell only its two x faces are new
                    ix = max(cx - r, 0) if on_face else cx - r
                    while ix <= min(cx + r, dims[0] - 1):
                        # the cell's own L1 lower bound: skip it unless it can hold a closer point
                        if ix >= 0 and gyz + _gap(vx, lo[0], cell, ix) <= best + slack:
                            c = (iz * dims[1] + iy) * dims[0] + ix
                            for j in range(starts[c], starts[c + 1]):
                                k = order[j]
                                d = (
                                    abs(points[k, 0] - vx)
                                    + abs(points[k, 1] - vy)
                                    + abs(points[k, 2] - vz)
                                )
                                if d < best:
                                    best = d
                        ix += step
        out[q] = best
    return out
