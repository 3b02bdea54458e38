"""
Overhead of the node graph: the full lockstep pipeline against the bare engine loop.

Runs, in one process and alternately, (a) the four nodes (trajectory publisher, MuJoCo simulator,
recorder replaying the bundled towel dynamic bag, evaluator scoring every real frame) at 100 Hz
and (b) MuJoCo stepped over the same targets in a plain loop, and prints pipeline / bare.
Goal: at most 1.10 at 100 Hz, 1.20 at 1 kHz.

    python benchmarks/bench_pipeline.py [--engine mujoco] [--rate 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.run_pipeline import run_pipeline, RunConfig

GOAL_100HZ, GOAL_1KHZ = 1.10, 1.20


def bare_loop(engine_name: str, rate: float, cloth: str, primitive: str) -> float:
    """
    Wall time of building the engine, reset and every step over the run's targets, nothing else.

    Engine construction (model compilation) is inside both timings, as the pipeline's simulator
    node builds its engine too.
    """
    targets = full_targets(primitive, rate)
    start = time.perf_counter()
    engine = make_engine(engine_name, rate, load_preset(engine_name, cloth, primitive))
    engine.reset(0, targets.left[0], targets.right[0])
    for k in range(1, len(targets)):
        engine.step(targets.left[k], targets.right[k])
    elapsed = time.perf_counter() - start
    engine.close()
    return elapsed


def pipeline(engine_name: str, rate: float, cloth: str, primitive: str) -> tuple[float, dict]:
    config = RunConfig(
        bag=bundled_bag(cloth, primitive),
        engines=[engine_name],
        rate_hz=rate,
        cloth=cloth,
        primitive=primitive,
    )
    start = time.perf_counter()
    summary = run_pipeline(config)
    return time.perf_counter() - start, summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--engine', default='mujoco')
    parser.add_argument('--rate', type=float, default=100.0)
    parser.add_argument('--cloth', default='towel')
    parser.add_argument('--primitive', default='dynamic')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    bare_loop(args.engine, args.rate, args.cloth, args.primitive)  # untimed: imports, caches
    pipeline(args.engine, args.rate, args.cloth, args.primitive)
    bare_times, pipe_times = [], []
    for _ in range(args.repeats):
        bare_times.append(bare_loop(args.engine, args.rate, args.cloth, args.primitive))
        elapsed, summary = pipeline(args.engine, args.rate, args.cloth, args.primitive)
        pipe_times.append(elapsed)
    bare, pipe = statistics.median(bare_times), statistics.median(pipe_times)
    frames = summary['real']['frames']
    print(
        f'{args.engine} {args.cloth} {args.primitive} at {args.rate:g} Hz,'
        f' {len(full_targets(args.primitive, args.rate))} steps, {frames} real frames scored'
    )
    print(
        f'bare engine loop : {bare:.3f} s (median of {args.repeats}:'
        f' {", ".join(f"{t:.3f}" for t in bare_times)})'
    )
    print(
        f'full pipeline    : {pipe:.3f} s (median of {args.repeats}:'
        f' {", ".join(f"{t:.3f}" for t in pipe_times)})'
    )
    goal = GOAL_100HZ if args.rate <= 100 else GOAL_1KHZ
    pairs = statistics.median(p / b for p, b in zip(pipe_times, bare_times))
    print(f'ratio pipeline / bare = {pipe / bare:.3f} (goal <= {goal})')
    print(f'median of the {args.repeats} back-to-back ratios = {pairs:.3f}')


if __name__ == '__main__':
    main()
