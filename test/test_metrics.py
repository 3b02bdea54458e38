"""The metrics equal a brute-force computation of docs/benchmark.md section 3."""

from cloth_bench_ros.core.metrics import (
    chamfer_l1,
    hausdorff_l1,
    latency_stats,
    RealCloud,
    stability,
    StabilityAccumulator,
)
import numpy as np
import pytest


def brute_force(V, P):
    d = np.abs(V[:, None, :] - P[None, :, :]).sum(axis=2).min(axis=1)
    return d.mean(), d.max()


@pytest.mark.parametrize('seed', range(5))
def test_chamfer_and_hausdorff_equal_brute_force_on_random_clouds(seed):
    rng = np.random.default_rng(seed)
    V = rng.normal(size=(rng.integers(1, 200), 3))
    P = rng.normal(size=(rng.integers(1, 2000), 3)) * rng.uniform(0.1, 3)
    cd, hd = brute_force(V, P)
    assert chamfer_l1(V, P) == pytest.approx(cd, rel=1e-12, abs=1e-15)
    assert hausdorff_l1(V, P) == pytest.approx(hd, rel=1e-12, abs=1e-15)
    assert hausdorff_l1(V, P) >= chamfer_l1(V, P)


def test_nearest_neighbour_is_taken_under_l1_not_l2():
    # From the origin: a = (0.9, 0, 0) is nearer in L1 (0.9 vs 1.2) but b = (0.4, 0.4, 0.4) nearer
    # in L2 (0.69 vs 0.9). The L1 metric must pick a.
    V = np.zeros((1, 3))
    P = np.array([[0.9, 0.0, 0.0], [0.4, 0.4, 0.4]])
    l2_choice = P[np.argmin(np.linalg.norm(P - V, axis=1))]
    assert np.abs(l2_choice).sum() == pytest.approx(1.2)
    assert chamfer_l1(V, P) == pytest.approx(0.9)
    assert hausdorff_l1(V, P) == pytest.approx(0.9)


def test_one_sided_distances_ignore_extra_real_points():
    V = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    P = np.vstack([V, [[50.0, 50.0, 50.0]]])  # a far outlier in P does not count
    assert chamfer_l1(V, P) == 0.0 and hausdorff_l1(V, P) == 0.0
    assert chamfer_l1(P, V) > 0  # but it does the other way round


def test_hausdorff_is_the_worst_vertex():
    V = np.array([[0.0, 0, 0], [0.0, 0, 0.3]])
    P = np.zeros((1, 3))
    assert chamfer_l1(V, P) == pytest.approx(0.15) and hausdorff_l1(V, P) == pytest.approx(0.3)


def test_real_cloud_scores_several_meshes_on_one_index():
    rng = np.random.default_rng(7)
    P = rng.uniform(size=(5000, 3))
    cloud = RealCloud(P)
    for _ in range(3):
        V = rng.uniform(size=(50, 3))
        cd, hd = cloud.chamfer_hausdorff(V)
        assert (cd, hd) == pytest.approx(brute_force(V, P), rel=1e-12)


@pytest.mark.parametrize('bad', [np.zeros((0, 3)), np.zeros((4, 2)), np.array([[0, 0, np.nan]])])
def test_bad_clouds_are_refused(bad):
    with pytest.raises(ValueError):
        chamfer_l1(bad, np.zeros((3, 3)))


def brute_stability(frames):
    N = len(frames)
    total = 0.0
    for t in range(1, N - 1):
        total += np.mean(np.abs((frames[t - 1] + frames[t] + frames[t + 1]) / 3 - frames[t]))
    return total / N


def test_stability_equals_its_definition():
    frames = np.random.default_rng(3).normal(size=(20, 30, 3))
    assert stability(frames) == pytest.approx(brute_stability(frames), rel=1e-12)


def test_stability_of_uniform_motion_is_zero_and_jitter_is_not():
    t = np.arange(10)[:, None, None]
    straight = np.ones((10, 5, 3)) * t * 0.01
    assert stability(straight) == pytest.approx(0.0, abs=1e-15)
    jitter = straight + 0.001 * (-1.0) ** t
    assert stability(jitter) == pytest.approx(8 / 10 * 2 * 0.001 * 2 / 3, rel=1e-9)


def test_online_stability_equals_batch():
    frames = np.random.default_rng(4).normal(size=(15, 8, 3))
    acc = StabilityAccumulator()
    for f in frames:
        acc.add(f)
    assert acc.value == stability(frames) and acc.count == 15


def test_latency_stats():
    s = latency_stats(np.arange(1, 101) / 1000)
    assert s.count == 100 and s.max == pytest.approx(0.1) and s.mean == pytest.approx(0.0505)
    assert s.p50 == pytest.approx(0.0505) and s.p99 == pytest.approx(
        np.percentile(np.arange(1, 101) / 1000, 99)
    )
    assert np.isnan(latency_stats(np.array([])).mean)


@pytest.mark.parametrize('frames_count', [1, 2, 3, 66, 67, 200])
def test_stability_in_blocks_equals_the_formula_frame_by_frame(frames_count):
    """The accumulator reduces frames in blocks; L_s equals the definition bit for bit."""
    frames = np.random.default_rng(frames_count).normal(size=(frames_count, 165, 3)) * 0.3
    acc = StabilityAccumulator()
    for f in frames:
        acc.add(f)
    total = 0.0
    for t in range(1, frames_count - 1):
        filtered = (frames[t - 1] + frames[t] + frames[t + 1]) / 3.0
        total += float(np.mean(np.abs(filtered - frames[t])))
    assert acc.count == frames_count
    assert acc.value == total / frames_count
