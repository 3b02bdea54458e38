"""
Step time of each available cloth engine at 10, 100 and 1000 Hz with the towel presets.

Runs the full trajectory (settle phase + quintic part) of a primitive on the default 11 x 15
grid, timing every engine.step() with perf_counter, and prints per engine and rate the
internal substeps, the median and 95th-percentile step time (up to a divergence), the
real-time factor (dt over the mean step time), the mean step time as a multiple of MuJoCo's at
the same rate (measured in this process, so the machine's load affects both alike) and whether
the engine diverged. Newton runs in
both of its cloth models (vbd, its preset's, and xpbd).

    .venv/bin/python benchmarks/bench_engine_step_time.py [--primitive dynamic] [--cloth towel]
        [--rates 10 100 1000] [--engines mujoco bullet] [--seconds 7.4] [--one-step-per-target]

--one-step-per-target sets the internal timestep to 1 / rate (as in the paper's frequency
study) instead of the preset's, so low rates show the engines' instability.
"""

from __future__ import annotations

import argparse
import time

from cloth_bench_ros.core.trajectory import full_targets, PRIMITIVES
from cloth_bench_ros.engines import known_engines, make_engine
from cloth_bench_ros.engines.presets import CLOTHS, load_preset
import numpy as np

# Cloth models timed per engine (overrides of the preset); engines not listed run their preset.
VARIANTS = {'newton': [{'model': 'vbd'}, {'model': 'xpbd'}]}
BASELINE = 'mujoco'


def time_steps(
    engine_name: str, rate_hz: float, params: dict, primitive: str, seconds: float | None
) -> tuple[np.ndarray, object]:
    """Wall time of every step of one run up to a divergence, and the engine after it."""
    targets = full_targets(primitive, rate_hz)
    n = len(targets) if seconds is None else min(len(targets), int(round(seconds * rate_hz)) + 1)
    engine = make_engine(engine_name, rate_hz, params)
    engine.reset(0, targets.left[0], targets.right[0])
    times = np.empty(n - 1)
    for k in range(1, n):
        start = time.perf_counter()
        engine.step(targets.left[k], targets.right[k])
        times[k - 1] = time.perf_counter() - start
        if engine.diverged:
            times = times[:k]
            break
    engine.close()
    return times, engine


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--primitive', default='dynamic', choices=PRIMITIVES)
    parser.add_argument('--cloth', default='towel', choices=CLOTHS)
    parser.add_argument('--rates', type=float, nargs='+', default=[10.0, 100.0, 1000.0])
    parser.add_argument(
        '--engines', nargs='+', default=None, help='default: every available engine'
    )
    parser.add_argument(
        '--seconds', type=float, default=None, help='only the first seconds of the run'
    )
    parser.add_argument(
        '--one-step-per-target', action='store_true', help='internal timestep = 1 / rate'
    )
    args = parser.parse_args()

    available = {i.name: i.version for i in known_engines() if i.available}
    engines = args.engines or sorted(available, key=lambda n: (n != BASELINE, n))
    print(f'{args.cloth} {args.primitive} preset, 11 x 15 grid; step time per engine.step()')
    print(
        f'{"engine":<28} {"rate Hz":>8} {"substeps":>8} {"median ms":>10} {"p95 ms":>8} '
        f'{"real-time x":>11} {"x " + BASELINE:>9}  diverged'
    )
    baseline: dict[float, float] = {}
    for name in engines:
        for variant in VARIANTS.get(name, [{}]):
            params = {**load_preset(name, args.cloth, args.primitive), **variant}
            label = f'{name} {available.get(name, "?")}' + (
                f' {variant["model"]}' if variant else ''
            )
            for rate in args.rates:
                run_params = (
                    {**params, 'timestep': 1.0 / rate, 'substeps': 1}
                    if args.one_step_per_target
                    else params
                )
                times, engine = time_steps(name, rate, run_params, args.primitive, args.seconds)
                d = engine.divergence
                realtime = (1.0 / rate) / times.mean()
                if name == BASELINE:
                    baseline[rate] = float(times.mean())
                ratio = f'{times.mean() / baseline[rate]:.2f}' if rate in baseline else '-'
                print(
                    f'{label:<28} {rate:>8g} {getattr(engine, "substeps", 1):>8}'
                    f' {1e3 * np.median(times):>10.3f} {1e3 * np.percentile(times, 95):>8.3f}'
                    f' {realtime:>11.2f} {ratio:>9} '
                    f' {f"at step {d.step}: {d.reason}" if d else "no"}',
                    flush=True,
                )


if __name__ == '__main__':
    main()
