"""
Metrics beside the paper's, against the simulated cloth's surface (docs/metrics.md).

The paper's CD/HD (core/metrics.py) run from the simulated vertices to the real points: they do not
see real cloth that the simulation misses, weight the cloth by its vertices, and check nothing
between them. These run between the real points P and the simulated surface S (the mesh's
triangles), in metres and the L1 norm like the paper's:

- reverse: the real points' exact distances to S (core/surface_distance.py): CD_reverse (their
  mean) and `recall` (the share within the threshold) over REVERSE_SAMPLES real points spread
  evenly over the cloud (`spread_subsample`; all of a frame that has no more), HD_reverse (their
  max) over every real point, exact (branch and bound over the real cloud's grid);
- surface: SURFACE_SAMPLES points of S stratified by area with a fixed seed (one in each of
  SURFACE_SAMPLES equal-area strata, `stratified_samples`), each one's distance to the nearest
  real point; mean CD_surface, max HD_surface, the share within the threshold `precision`;
- two-sided: CD_two_sided = (CD_reverse + CD_surface) / 2, HD_two_sided = the larger HD;
  F = 2 precision recall / (precision + recall) at FSCORE_THRESHOLD_M;
- EMD: the optimal-transport (earth mover's) distance, L1 ground cost, uniform weights, between
  OT_SAMPLES real points spread evenly over the cloud (`spread_subsample`) and OT_SAMPLES points
  of S stratified by area (`stratified_samples`), exact (POT's network simplex).

The simulated cloth's table contact (core/evaluation.py) is checked on points drawn uniformly by
area (`surface_samples`), as many as the real frame has up to core.phase.CONTACT_SAMPLES.

One thread by default. `CLOTH_BENCH_METRIC_THREADS=2` in the environment (or `set_threads(2)`)
runs the parts that do not depend on each other at once: the area samples to the real points and
the EMD on one reusable worker thread (compiled with nogil, they release the GIL), the real points
to the triangles and HD_reverse in the calling thread; the same numbers, bit for bit. It pays
only where a second core is idle (docs/metrics.md).
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
import math
import os
import threading
from typing import Callable, TypeVar

from cloth_bench_ros.core.metrics import RealCloud
from cloth_bench_ros.core.nearest import PointGrid
from cloth_bench_ros.core.phase import CONTACT_SAMPLES
from cloth_bench_ros.core.surface_distance import grid_faces, TriangleMesh
from numba import njit
import numpy as np

# Raised whenever a change moves a value of these metrics (2: uniform within strata, one contact
# band): it is in every run's summary and in the keys of kept results scored on them.
SURFACE_REVISION = 2
SURFACE_SAMPLES = 500  # points of the simulated surface, one per equal-area stratum
SURFACE_SEED = 0
REVERSE_SAMPLES = 500  # real points in CD_reverse and recall (HD_reverse: every point)
REVERSE_SEED = 0
FSCORE_THRESHOLD_M = 0.01  # L1
OT_SAMPLES = 80  # points of each side in the optimal-transport problem, spread (floor: docs)
OT_SEED = 0
THREADS_VARIABLE = 'CLOTH_BENCH_METRIC_THREADS'  # '2': a worker thread beside the caller

_T = TypeVar('_T')
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()
_threads = 2 if os.environ.get(THREADS_VARIABLE, '').strip() == '2' else 1


def set_threads(threads: int) -> None:
    """Run the surface metrics' independent parts on 1 thread (the default) or 2."""
    global _threads
    if threads not in (1, 2):
        raise ValueError(f'threads must be 1 or 2, not {threads!r}')
    _threads = threads


def metric_threads() -> int:
    """Return how many threads the surface metrics use: 1, or 2 when set so."""
    return _threads


def _start(fn: Callable[[], _T]) -> Callable[[], _T]:
    """Start fn on the worker thread (created when first needed); return its result's getter."""
    if _threads == 1:
        result = fn()
        return lambda: result
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=1, thread_name_prefix='surface-metrics')
        future: Future[_T] = _POOL.submit(fn)
    return future.result


@dataclass(frozen=True)
class SurfaceScores:
    """The surface metrics of one frame (m, except the shares and F in [0, 1])."""

    cd_reverse: float
    hd_reverse: float
    cd_surface: float
    hd_surface: float
    cd_two_sided: float
    hd_two_sided: float
    precision: float
    recall: float
    fscore: float
    emd: float

    def as_dict(self) -> dict[str, float]:
        # Not dataclasses.asdict: it deep-copies field by field, and this runs for every frame.
        return {name: getattr(self, name) for name in SURFACE_FIELDS}


SURFACE_FIELDS = tuple(SurfaceScores.__dataclass_fields__)
NAN_SCORES = SurfaceScores(*([math.nan] * len(SURFACE_FIELDS)))


@lru_cache(maxsize=8)
def _uniforms(n: int, seed: int) -> np.ndarray:
    """
    Return the fixed draws behind the surface samples: (n, 3) in [0, 1).

    In increasing order of the triangle draw (column 0): the samples then come triangle after
    triangle, neighbours next to each other, and the nearest-point searches for them read the
    real cloud's grid in order (a fifth faster than in the order drawn; the same set of points).
    """
    draws = np.random.default_rng(seed).random((n, 3))
    draws = draws[np.argsort(draws[:, 0], kind='stable')]
    draws.setflags(write=False)
    return draws


def surface_samples(
    vertices: np.ndarray, faces: np.ndarray, n: int = CONTACT_SAMPLES, seed: int = SURFACE_SEED
) -> np.ndarray:
    """
    Return n points of the mesh's surface, uniformly by area, from fixed draws.

    A triangle is picked with probability proportional to its area and a point in it uniformly
    (barycentric (1 - sqrt(u), sqrt(u) (1 - w), sqrt(u) w)); the same draws for every frame, so
    a frame's samples move with its mesh.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    return _area_samples(v, f, _uniforms(int(n), int(seed)))


@njit(cache=True, nogil=True)
def _area_samples(v, f, r):
    areas = np.empty(f.shape[0])
    for t in range(f.shape[0]):
        a, b, c = v[f[t, 0]], v[f[t, 1]], v[f[t, 2]]
        u, w = b - a, c - a
        nx = u[1] * w[2] - u[2] * w[1]
        ny = u[2] * w[0] - u[0] * w[2]
        nz = u[0] * w[1] - u[1] * w[0]
        areas[t] = 0.5 * np.sqrt(nx * nx + ny * ny + nz * nz)
    if not areas.sum() > 0:  # collapsed to a line or a point: every triangle alike
        areas[:] = 1.0
    cdf = np.cumsum(areas)
    out = np.empty((r.shape[0], 3))
    for k in range(r.shape[0]):
        t = min(np.searchsorted(cdf, r[k, 0] * cdf[-1], side='right'), f.shape[0] - 1)
        root, w = np.sqrt(r[k, 1]), r[k, 2]
        a, b, c = v[f[t, 0]], v[f[t, 1]], v[f[t, 2]]
        out[k] = a + root * (1.0 - w) * (b - a) + root * w * (c - a)
    return out


def stratified_samples(
    vertices: np.ndarray, faces: np.ndarray, n: int, seed: int = SURFACE_SEED
) -> np.ndarray:
    """
    Return n points of the mesh's surface stratified by area, from fixed draws.

    The triangles, in their order, are cut into n strata of equal area and one point is drawn
    uniformly by area in each (as `surface_samples`, its triangle pick confined to stratum i): a
    sample spread over the whole surface: its mean distance to a cloud varies far less from
    frame to frame than a random sample's, and its distance to another such sample of the same
    surface (the optimal-transport floor) is far smaller.
    """
    v = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    return _area_samples(v, f, _strata(int(n), int(seed)))


@lru_cache(maxsize=8)
def _strata(n: int, seed: int) -> np.ndarray:
    """
    Return fixed draws (n, 3) in [0, 1), the triangle draw of row i in [i / n, (i + 1) / n).

    In the order drawn, not `_uniforms`' sorted one: a sorted offset would rise from 0 to 1
    across the strata instead of being uniform within each.
    """
    draws = np.random.default_rng(seed).random((n, 3))
    draws[:, 0] = (np.arange(n) + draws[:, 0]) / n
    draws.setflags(write=False)
    return draws


def spread_subsample(grid: PointGrid, n: int, seed: int = REVERSE_SEED) -> np.ndarray:
    """
    Return the indices of n of the grid's points spread evenly over it (all when no more).

    Every (size / n)-th point in the grid's cell order (cell after cell), from an offset drawn
    with the fixed seed: a sample stratified in space, so its mean distance stays close to all
    points' even where the distances differ from one part of the cloth to another.
    """
    size = len(grid.order)
    if size <= n:
        return np.arange(size)
    return grid.order[((_steps(n, seed)) * (size / n)).astype(np.int64)]


@lru_cache(maxsize=8)
def _steps(n: int, seed: int) -> np.ndarray:
    """Return 0 .. n - 1 plus one offset in [0, 1) drawn with the seed (fixed: cached)."""
    steps = np.arange(n) + np.random.default_rng(seed).random()
    steps.setflags(write=False)
    return steps


def transport_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Exact earth mover's distance between two clouds: L1 ground cost, uniform weights (POT)."""
    from scipy.spatial.distance import cdist  # lazy: +0.34 s at the evaluator's start

    cost = cdist(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), 'cityblock')
    return _transport_solver()(np.full(len(a), 1.0 / len(a)), np.full(len(b), 1.0 / len(b)), cost)


@lru_cache(maxsize=1)
def _transport_solver() -> Callable[[np.ndarray, np.ndarray, np.ndarray], float]:
    """
    Return POT's exact solver for (weights a, weights b, cost) -> the optimal cost.

    Imported where first used (studies that never ask for it never pay for it). POT's compiled
    network simplex (`ot.lp.emd_wrap.emd_c`, what `ot.emd2` calls) directly where this POT has
    it: the same number, without emd2's checks, which cost a third of its time on 80 x 80
    problems whose weights are uniform by construction; `ot.emd2` otherwise.
    """
    import ot  # lazy: POT, +1.1 s at the evaluator's start; the transport metric only

    emd_c = getattr(getattr(ot.lp, 'emd_wrap', None), 'emd_c', None)
    check = getattr(getattr(ot.lp, 'emd_wrap', None), 'check_result', None)

    def emd2(wa: np.ndarray, wb: np.ndarray, cost: np.ndarray) -> float:
        return float(ot.emd2(
            wa, wb, cost, numItermax=1_000_000, check_marginals=False, center_dual=False
        ))

    if emd_c is None or check is None:
        return emd2

    def direct(wa: np.ndarray, wb: np.ndarray, cost: np.ndarray) -> float:
        _, value, _, _, result = emd_c(wa, wb, np.ascontiguousarray(cost), 1_000_000, 1)
        check(result)  # warns as emd2 does when the solver stopped early
        return float(value)

    try:  # this POT's signature: the same value as emd2 on a small problem
        probe = np.array([[0.0, 1.0], [2.0, 0.5]])
        half = np.full(2, 0.5)
        if direct(half, half, probe) == emd2(half, half, probe):
            return direct
    except (TypeError, ValueError):
        pass
    return emd2


def surface_scores(
    cloud: RealCloud,
    vertices: np.ndarray,
    faces: np.ndarray,
    threshold: float = FSCORE_THRESHOLD_M,
    transport: bool = True,
    samples: np.ndarray | None = None,
) -> SurfaceScores:
    """Return the surface metrics of a simulated mesh (vertices, faces) against a real cloud."""
    if samples is None:
        samples = stratified_samples(vertices, faces, SURFACE_SAMPLES, SURFACE_SEED)

    def from_surface() -> tuple[np.ndarray, float]:  # on the worker thread: no shared writes
        emd = math.nan
        if transport:
            real = cloud.points[spread_subsample(cloud.grid, OT_SAMPLES, OT_SEED)]
            surface = stratified_samples(vertices, faces, OT_SAMPLES, OT_SEED)
            emd = transport_distance(real, surface)
        return cloud.nearest_l1(samples), emd

    surface_part = _start(from_surface)
    mesh = TriangleMesh(vertices, faces)
    reverse = cloud.points[spread_subsample(cloud.grid, REVERSE_SAMPLES)]
    to_surface = mesh.distances(reverse)
    hd_r = mesh.farthest(
        cloud.grid, float(to_surface.max()), samples, measured=(reverse, to_surface)
    )
    to_real, emd = surface_part()
    cd_s, hd_s = float(to_real.mean()), float(to_real.max())
    cd_r = float(to_surface.mean())
    precision = float(np.count_nonzero(to_real <= threshold)) / len(to_real)
    recall = float(np.count_nonzero(to_surface <= threshold)) / len(to_surface)
    fscore = (
        2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    )
    return SurfaceScores(
        cd_reverse=cd_r,
        hd_reverse=hd_r,
        cd_surface=cd_s,
        hd_surface=hd_s,
        cd_two_sided=0.5 * (cd_r + cd_s),
        hd_two_sided=max(hd_r, hd_s),
        precision=precision,
        recall=recall,
        fscore=fscore,
        emd=emd,
    )


def settings() -> dict[str, float | int | str]:
    """Return what the surface metrics were computed with, for a run's summary."""
    return {
        'revision': SURFACE_REVISION,
        'norm': 'L1',
        'surface_samples': SURFACE_SAMPLES,
        'surface_sampling': 'one per equal-area stratum of the triangles in their order',
        'surface_seed': SURFACE_SEED,
        'contact_samples': f'as many as the real frame has, at most {CONTACT_SAMPLES}',
        'reverse_samples': REVERSE_SAMPLES,
        'reverse_seed': REVERSE_SEED,
        'reverse_subsample': 'spread evenly: every (n / reverse_samples)-th in grid cell order',
        'hd_reverse': 'every real point, exact',
        'fscore_threshold_m': FSCORE_THRESHOLD_M,
        'ot_samples': OT_SAMPLES,
        'ot_seed': OT_SEED,
        'ot_subsample': 'real: spread evenly as reverse_subsample; surface: one per equal-area'
        ' stratum',
        'ot_ground_cost': 'L1',
    }


def compile_kernels() -> None:
    """Score a small frame so that every compiled kernel of the metrics is in numba's cache."""
    rng = np.random.default_rng(0)
    x, z = np.meshgrid(np.linspace(0.0, 0.5, 4), np.linspace(0.0, 0.7, 5))  # index j * 4 + i
    vertices = np.stack([x.ravel(), np.full(x.size, 0.5), z.ravel()], axis=1)
    faces = grid_faces(4, 5)
    cloud = RealCloud(vertices[rng.integers(0, len(vertices), 200)] + 0.01 * rng.random((200, 3)))
    surface_scores(cloud, vertices, faces)  # the nearest-point and area-sample kernels too
