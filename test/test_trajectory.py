"""The quintic trajectories meet docs/benchmark.md's boundary conditions at every rate."""

import math

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.quintic import QuinticSegment
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import (
    CSV_HEADER,
    full_targets,
    Primitive,
    quaternion_xyz,
    sample_quintic,
    sample_times,
    to_csv,
)
import numpy as np
import pytest

RATES = (10.0, 100.0, 1000.0)
Y0, Z0 = 0.0, 1.0
DEG = math.pi / 180

# (axis, [(t_end of segment, (p, v, a) at that end)]) straight from docs/benchmark.md section 2.
DYNAMIC_ENDS = {
    'y': [
        (0.0, (Y0, 0, 0)),
        (1.1, (Y0 - 0.25, -0.7, 3.0)),
        (2.6, (Y0 + 0.30, 0.0, -1.0)),
        (3.9, (Y0 + 0.15, -0.3, -0.5)),
        (4.4, (Y0 - 0.10, 0.0, 0.0)),
    ],
    'z': [
        (0.0, (Z0, 0, 0)),
        (1.1, (Z0 + 0.06, 0, 0)),
        (2.6, (Z0 + 0.06, 0, 0)),
        (3.9, (Z0 - 0.51051, 0, 0.02)),
        (4.4, (Z0 - 0.51051, 0, 0)),
    ],
    'roll': [
        (0.0, (-179.24297822 * DEG, 0, 0)),
        (1.1, (-140 * DEG, 10.8 * DEG, 180 * DEG)),
        (2.6, (-220 * DEG, -10 * DEG, -180 * DEG)),
        (3.9, (-140 * DEG, 0, 0)),
        (4.4, (-140 * DEG, 0, 0)),
    ],
}
QUASI_ENDS = {
    'y': [(0.0, (Y0, 0, 0)), (2.0, (Y0, 0, 0)), (14.0, (Y0 - 0.60, 0, 0))],
    'z': [
        (0.0, (Z0, 0, 0)),
        (1.0, (Z0 - 0.05, 0, 0)),
        (2.0, (Z0 - 0.05, 0, 0)),
        (8.0, (Z0 - 0.31051, 0, 0.02)),
        (14.0, (Z0 - 0.31051, 0, 0)),
    ],
}


@pytest.mark.parametrize('rate', RATES)
@pytest.mark.parametrize(
    'primitive,ends', [(Primitive.DYNAMIC, DYNAMIC_ENDS), (Primitive.QUASI_STATIC, QUASI_ENDS)]
)
def test_segment_ends_meet_reference_at_sample_times(primitive, ends, rate):
    task = load_task(primitive.value)
    t = sample_times(task.duration, rate)
    for axis, points in ends.items():
        chain = {'y': task.left[1], 'z': task.left[2], 'roll': task.roll}[axis]
        pos, vel, acc = chain.evaluate(t)
        for t_end, (p, v, a) in points:
            k = int(round(t_end * rate))
            assert abs(t[k] - t_end) < 1e-12
            assert pos[k] == pytest.approx(p, abs=1e-9), (axis, t_end)
            assert vel[k] == pytest.approx(v, abs=1e-9), (axis, t_end)
            assert acc[k] == pytest.approx(a, abs=1e-9), (axis, t_end)


@pytest.mark.parametrize('primitive', list(Primitive))
def test_segments_join_continuously_in_position_and_velocity(primitive):
    task = load_task(primitive.value)
    for chain in (task.left[1], task.left[2], task.roll):
        if not hasattr(chain, 'segments'):
            continue
        for seg, nxt in zip(chain.segments, chain.segments[1:]):
            p1, v1, _ = seg.evaluate(seg.duration)
            p2, v2, _ = nxt.evaluate(0.0)
            assert p1 == pytest.approx(p2, abs=1e-9) and v1 == pytest.approx(v2, abs=1e-9)


def test_quintic_segment_solves_its_boundary_conditions():
    seg = QuinticSegment(1.3, (0.3, 0.0, -1.0), (0.15, -0.3, -0.5))
    for t, expected in ((0.0, seg.start), (1.3, seg.end)):
        assert np.allclose(seg.evaluate(t), expected, atol=1e-12)


def test_same_function_of_time_at_every_rate():
    """Sampling is analytic: the 10 Hz samples are every 10th of the 100 Hz ones."""
    coarse, fine = sample_quintic('dynamic', 10.0), sample_quintic('dynamic', 100.0)
    assert len(coarse) == 45 and len(fine) == 441
    assert np.allclose(coarse.left, fine.left[::10], atol=1e-12)
    assert np.allclose(coarse.roll, fine.roll[::10], atol=1e-12)


def test_grippers_share_y_z_and_keep_their_x():
    tg = sample_quintic('quasi_static', 100.0)
    assert np.all(tg.left[:, 0] == 0.02) and np.all(tg.right[:, 0] == 0.498)
    assert np.array_equal(tg.left[:, 1:], tg.right[:, 1:])
    assert len(tg) == 1401


def test_full_targets_start_with_the_settle_phase():
    tg = full_targets('dynamic', 100.0)
    grasp_left = np.array(load_task('dynamic').grasp[0])
    assert tg.quintic_start == 3.0 and tg.quintic_index == 300
    assert np.allclose(tg.left[0], scene.GRIPPER_START_LEFT) and np.allclose(
        tg.right[100], scene.GRIPPER_START_RIGHT
    )
    assert np.allclose(tg.left[150], (scene.GRIPPER_START_LEFT + grasp_left) / 2)
    assert np.allclose(tg.left[200:301], grasp_left)
    quintic = sample_quintic('dynamic', 100.0)
    assert np.allclose(tg.left[300:], quintic.left, atol=1e-12)
    assert tg.stamp_ns(300) == 3_000_000_000


def test_quaternion_matches_rotation_matrix_of_extrinsic_xyz():
    r, p, y = 0.3, -0.2, 0.9
    qx, qy, qz, qw = quaternion_xyz(r, p, y)
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx
    Rq = np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )
    assert np.allclose(R, Rq, atol=1e-12)


def test_csv_has_the_documented_header_and_units():
    text = to_csv(sample_quintic('dynamic', 10.0))
    lines = text.splitlines()
    assert lines[0] == CSV_HEADER
    assert len(lines) == 46
    last = [float(x) for x in lines[-1].split(',')]
    assert last[0] == pytest.approx(4.4) and last[3] == pytest.approx(Z0 - 0.51051)
    assert last[4] == pytest.approx(-140 * DEG)


@pytest.mark.parametrize('rate', [0.0, -5.0, float('nan')])
def test_bad_rate_is_refused(rate):
    with pytest.raises(ValueError, match='rate'):
        sample_times(1.0, rate)
