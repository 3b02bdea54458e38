"""Hardware-in-the-loop timing: MuJoCo with targets paced by the wall clock at 100 and 1000 Hz.

Runs the four nodes with pacing="realtime" (the trajectory publisher sends target k at wall time
k / rate, as a robot controller would) on the towel preset and the bundled towel bag, and prints
per rate: per-step latency (the target's due time on that schedule -> state received, so a run
that falls behind its schedule shows it) p50 / p99 / max, deadline misses
(latency > 1 / rate), the real-time factor (simulated over wall time) and the engine's step time.

    .venv/bin/python benchmarks/bench_realtime.py [--engine mujoco] [--rates 100 1000]
        [--cloth towel] [--primitive dynamic] [--bag PATH] [--grid 11x15] [--repeats 1]

Run it on an otherwise idle machine: other processes on the same cores show up as misses.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.studies.pipeline import RunConfig, run_pipeline
from cloth_bench_ros.studies.sweep import parse_grid
from cloth_bench_ros.core.trajectory import PRIMITIVES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default="mujoco")
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 1000.0])
    parser.add_argument("--cloth", default="towel")
    parser.add_argument("--primitive", default="dynamic", choices=PRIMITIVES)
    parser.add_argument("--bag", help="default: the bundled bag of the cloth and primitive")
    parser.add_argument("--grid", type=parse_grid, default=None, help="NXxNZ (default: the engine's 11x15)")
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()

    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{args.engine}, {args.cloth} {args.primitive} preset, grid {args.grid or 'default'}, realtime pacing; "
          f"bag {bag}; load average {load:.2f} on {os.cpu_count()} cores")
    header = (f"{'rate Hz':>8} {'run':>4} {'steps':>6} {'lat p50 ms':>10} {'lat p99 ms':>10} {'lat max ms':>10} "
              f"{'misses':>16} {'RTF':>6} {'step p50 ms':>11} {'step p99 ms':>11} {'step max ms':>11}")
    print(header)
    print("-" * len(header))
    for rate in args.rates:
        for run in range(args.repeats):
            summary = run_pipeline(RunConfig(bag=bag, engines=[args.engine], rate_hz=rate, cloth=args.cloth,
                                             primitive=args.primitive, pacing="realtime", grid=args.grid))
            m = summary["engines"][args.engine]
            lat, st = m["latency"], m["step_time"]
            n = lat["count"]
            misses = f"{m['deadline_misses']} ({100 * m['deadline_misses'] / max(n, 1):.1f} %)"
            print(f"{rate:>8g} {run:>4} {n:>6} {lat['p50'] * 1e3:>10.3f} {lat['p99'] * 1e3:>10.3f} "
                  f"{lat['max'] * 1e3:>10.3f} {misses:>16} {m['real_time_factor']:>6.3f} {st['p50'] * 1e3:>11.3f} "
                  f"{st['p99'] * 1e3:>11.3f} {st['max'] * 1e3:>11.3f}"
                  + (f"  diverged at step {m['diverged_at_step']}" if m["diverged"] else ""))
    print("latency: the target's due time on the wall-clock schedule (first target + k / rate) -> state received, "
          "so falling behind counts; miss: latency > 1 / rate; RTF: simulated time / wall time")


if __name__ == "__main__":
    main()
