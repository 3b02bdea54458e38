"""
Metrics beside the paper's, against the simulated cloth's surface (docs/metrics.md).

The paper's CD/HD (core/metrics.py) run from the simulated vertices to the real points: they do not
see real cloth that the simulation misses, weight the cloth by its vertices, and check nothing
between them. These run between the real points P and the simulated surface S (the mesh's
triangles), in metres and the L1 norm like the paper's:

- reverse: each real point's exact distance to S (core/surface_distance.py); its mean CD_reverse,
  its max HD_reverse, the share within the threshold `recall`;
- surface: SURFACE_SAMPLES points of S drawn uniformly by area with a fixed seed, each one's
  distance to the nearest real point; mean CD_surface, max HD_surface, the share within the
  threshold `precision`;
- two-sided: CD_two_sided = (CD_reverse + CD_surface) / 2, HD_two_sided = the larger HD;
  F = 2 precision recall / (precision + recall) at FSCORE_THRESHOLD_M;
- EMD: the optimal-transport (earth mover's) distance, L1 ground cost, uniform weights, between
  OT_SAMPLES real points (a fixed-seed subsample) and the first OT_SAMPLES surface samples, exact
  (POT's network simplex).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache
import math

from cloth_bench_ros.core.metrics import RealCloud
from cloth_bench_ros.core.surface_distance import TriangleMesh
import numpy as np

SURFACE_SAMPLES = 1000  # points drawn on the simulated surface, uniformly by area
SURFACE_SEED = 0
FSCORE_THRESHOLD_M = 0.01  # L1
OT_SAMPLES = 128  # points of each side in the optimal-transport problem (its floor: docs)
OT_SEED = 0


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
        return asdict(self)


SURFACE_FIELDS = tuple(SurfaceScores.__dataclass_fields__)
NAN_SCORES = SurfaceScores(*([math.nan] * len(SURFACE_FIELDS)))


@lru_cache(maxsize=8)
def _uniforms(n: int, seed: int) -> np.ndarray:
    """Return the fixed draws behind the surface samples: (n, 3) in [0, 1)."""
    draws = np.random.default_rng(seed).random((n, 3))
    draws.setflags(write=False)
    return draws


def surface_samples(
    vertices: np.ndarray, faces: np.ndarray, n: int = SURFACE_SAMPLES, seed: int = SURFACE_SEED
) -> np.ndarray:
    """
    Return n points of the mesh's surface, uniformly by area, from fixed draws.

    A triangle is picked with probability proportional to its area and a point in it uniformly
    (barycentric (1 - sqrt(u), sqrt(u) (1 - w), sqrt(u) w)); the same draws for every frame, so
    a frame's samples move with its mesh.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    if not areas.sum() > 0:  # collapsed to a line or a point: every triangle alike
        areas = np.ones(len(f))
    cdf = np.cumsum(areas)
    r = _uniforms(int(n), int(seed))
    tri = np.minimum(np.searchsorted(cdf, r[:, 0] * cdf[-1], side='right'), len(f) - 1)
    root = np.sqrt(r[:, 1])[:, None]
    w = r[:, 2][:, None]
    return a[tri] + root * (1.0 - w) * (b[tri] - a[tri]) + root * w * (c[tri] - a[tri])


@lru_cache(maxsize=8)
def _subsample(size: int, n: int, seed: int) -> np.ndarray:
    """Return fixed indices of n of `size` points (all of them when there are no more)."""
    if size <= n:
        return np.arange(size)
    return np.sort(np.random.default_rng(seed).choice(size, n, replace=False))


def transport_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Exact earth mover's distance between two clouds: L1 ground cost, uniform weights (POT)."""
    import ot  # POT, imported where used: studies that never ask for it never pay for it
    from scipy.spatial.distance import cdist

    cost = cdist(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), 'cityblock')
    wa = np.full(len(a), 1.0 / len(a))
    wb = np.full(len(b), 1.0 / len(b))
    return float(ot.emd2(wa, wb, cost, numItermax=1_000_000))


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
        samples = surface_samples(vertices, faces)
    to_real = cloud.nearest_l1(samples)
    to_surface = TriangleMesh(vertices, faces).distances(cloud.points)
    cd_s, hd_s = float(to_real.mean()), float(to_real.max())
    cd_r, hd_r = float(to_surface.mean()), float(to_surface.max())
    precision = float(np.count_nonzero(to_real <= threshold)) / len(to_real)
    recall = float(np.count_nonzero(to_surface <= threshold)) / len(to_surface)
    fscore = (
        2.0 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    )
    emd = math.nan
    if transport:
        real = cloud.points[_subsample(len(cloud.points), OT_SAMPLES, OT_SEED)]
        emd = transport_distance(real, samples[:OT_SAMPLES])
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
        'norm': 'L1',
        'surface_samples': SURFACE_SAMPLES,
        'surface_seed': SURFACE_SEED,
        'fscore_threshold_m': FSCORE_THRESHOLD_M,
        'ot_samples': OT_SAMPLES,
        'ot_seed': OT_SEED,
        'ot_ground_cost': 'L1',
    }
