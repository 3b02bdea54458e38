"""A bag made by an engine with known parameters (the identification tests' ground truth)."""

from __future__ import annotations

from pathlib import Path

from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.data import BagWriter, TrialInfo
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
import numpy as np

FPS = 30.0
SETTLE_DURATION = load_task('dynamic').settle_duration


def write_engine_target_bag(
    path: Path,
    engine: str,
    params: dict,
    grid: tuple[int, int],
    frames: int,
    rate_hz: float = 100.0,
    seed: int = 0,
    cloth: str = 'towel',
    primitive: str = 'dynamic',
) -> Path:
    """
    Return the engine's own vertices at 30 Hz (linear between steps, as the evaluator pairs).

    A bag whose noise floor is 0 for the same engine, seed and parameters.
    """
    targets = full_targets(primitive, rate_hz)
    sim = make_engine(
        engine, rate_hz, {**load_preset(engine, cloth, primitive), **params}, ClothGrid(*grid)
    )
    states = [sim.reset(seed, targets.left[0], targets.right[0]).copy()]
    last = SETTLE_DURATION + (frames - 1) / FPS
    while len(states) / rate_hz <= last + 2 / rate_hz:
        k = len(states)
        states.append(np.array(sim.step(targets.left[k], targets.right[k]), dtype=float))
    sim.close()
    trial = TrialInfo(
        cloth=cloth,
        trial=0,
        primitive=primitive,
        change_of_phase_frame=frames + 10,
        source=f'test: {engine} with {params}',
    )
    with BagWriter(path, trial=trial) as bag:
        for k in range(frames):
            t_ns = round(k * 1e9 / FPS)
            run_ns = t_ns + round(SETTLE_DURATION * 1e9)
            i = int(run_ns * rate_hz // 1_000_000_000)
            s0, s1 = targets.stamp_ns(i), targets.stamp_ns(i + 1)
            w = (run_ns - s0) / (s1 - s0)
            bag.write_cloud(
                '/cloth_bench/real/cloud', t_ns, (1 - w) * states[i] + w * states[i + 1]
            )
    return path
