"""Each engine's worst frame: chosen by the evaluator's core, kept beside summary.json, read."""

from __future__ import annotations

from cloth_bench_ros.core.evaluation import OnlineEvaluator
from cloth_bench_ros.core.trajectory import Primitive
from cloth_bench_ros.core.worst_frames import (
    read_worst_frames,
    WORST_FRAMES_FILE,
    WorstFrameError,
    write_worst_frames,
)
import numpy as np
import pytest

FRAME_NS = 1_000_000_000 // 30


def _scored(tmp_path):
    """Two engines, six frames; 'b' is off by more in frame 4, which is outside the window."""
    rng = np.random.default_rng(3)
    core = OnlineEvaluator(['a', 'b'], Primitive.DYNAMIC, 0, change_of_phase_frame=4)
    heard = []
    core.listeners.append(heard.append)
    real = rng.uniform(-0.2, 0.2, size=(300, 3))
    for k in range(6):
        stamp = k * FRAME_NS
        base = real[:40] + 0.001 * k
        core.add_state('a', stamp, base + 0.002 * k)
        core.add_state('b', stamp, base + (0.05 if k == 4 else 0.01 * (k == 2)))
        core.add_real(stamp, real)
    return core, heard


def test_the_core_hands_each_scored_frame_with_its_per_vertex_errors(tmp_path):
    core, heard = _scored(tmp_path)
    assert [s.score for s in heard] == core.scores and len(heard) == 12
    for s in heard:  # CD and HD are the mean and maximum of the very errors handed out
        assert s.errors.shape == (40,) and s.score.cd == float(s.errors.mean())
        assert s.score.hd == float(s.errors.max())
    # the worst frame is the largest CD inside the window (frames 0-3), not frame 4
    assert core.worst['b'].score.frame == 2 and core.worst['a'].score.frame == 3
    assert max(s.score.cd for s in heard if s.score.engine == 'b') > core.worst['b'].score.cd


def test_worst_frames_round_trip_and_a_bad_file_is_one_line(tmp_path):
    core, _ = _scored(tmp_path)
    path = write_worst_frames(tmp_path, core.worst)
    assert path == tmp_path / WORST_FRAMES_FILE
    frames = {f.engine: f for f in read_worst_frames(path)}
    for engine, kept in core.worst.items():
        f = frames[engine]
        assert (f.frame, f.cd, f.hd) == (kept.score.frame, kept.score.cd, kept.score.hd)
        np.testing.assert_array_equal(f.errors, kept.errors)
        np.testing.assert_array_equal(f.vertices, kept.vertices)
        assert f.real.shape == kept.real.shape
    assert write_worst_frames(tmp_path / 'none', {}) is None
    bad = tmp_path / 'bad.npz'
    bad.write_bytes(b'not a zip')
    with pytest.raises(WorstFrameError, match='bad.npz: not a worst-frames file'):
        read_worst_frames(bad)
