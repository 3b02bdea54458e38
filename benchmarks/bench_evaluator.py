"""Cost of scoring one real frame: CD + HD of the simulated mesh against a 50,000-point cloud.

Prints the evaluator's k-d tree (build once per real frame, L1 query per mesh) beside brute force
(all pairwise L1 distances), both in this process on the same data, and checks they agree.

    python benchmarks/bench_evaluator.py [--points 50000] [--vertices 165]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from cloth_bench_ros.core.metrics import RealCloud
from cloth_bench_ros.core.scene import ClothGrid


def brute_force(V: np.ndarray, P: np.ndarray) -> tuple[float, float]:
    d = np.empty(len(V))
    for i in range(0, len(V), 16):  # blocks of vertices keep memory bounded
        d[i:i + 16] = np.abs(V[i:i + 16, None, :] - P[None, :, :]).sum(axis=2).min(axis=1)
    return float(d.mean()), float(d.max())


def best_of(fn, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return min(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=50_000)
    parser.add_argument("--nx", type=int, default=11)
    parser.add_argument("--nz", type=int, default=15)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    grid = ClothGrid(args.nx, args.nz)
    V = grid.vertices() + rng.normal(scale=0.02, size=(grid.nx * grid.nz, 3))
    P = grid.vertices()[rng.integers(0, grid.nx * grid.nz, args.points)] + rng.normal(scale=0.03, size=(args.points, 3))
    t_tree, tree_result = best_of(lambda: RealCloud(P).chamfer_hausdorff(V), args.repeats)
    t_query, _ = best_of(lambda cloud=RealCloud(P): cloud.chamfer_hausdorff(V), args.repeats)
    t_brute, brute_result = best_of(lambda: brute_force(V, P), max(1, args.repeats // 2))
    assert np.allclose(tree_result, brute_result, rtol=1e-12), (tree_result, brute_result)
    print(f"{len(V)} mesh vertices against {len(P)} real points (best of {args.repeats})")
    print(f"evaluator (k-d tree build + L1 query): {t_tree * 1e3:8.2f} ms per real frame")
    print(f"  of which the query for one mesh     : {t_query * 1e3:8.2f} ms")
    print(f"brute force (all pairwise L1)        : {t_brute * 1e3:8.2f} ms per real frame")
    print(f"speed-up brute / evaluator = {t_brute / t_tree:.1f}x; CD = {tree_result[0]:.5f} m, HD = {tree_result[1]:.5f} m")


if __name__ == "__main__":
    main()
