"""
Multi-fidelity identification against today's: engine-seconds and held-out CD.

On the bundled towel fling (the MuJoCo-made reference), each engine is identified with
`--trials auto`: every trial over the whole motion (`--fidelity full`, today's) and with each
multi-fidelity rung of `--fidelities` (default coarse: trials screened on a coarser mesh; prune:
trials pruned on the first quarter of the motion). The script prints, per
engine, the engine-seconds of each identification (the sum of its trials' `cpu_s`: what the trials
cost on an idle core, pruned ones included), the identified parameters' CD on held-out seeds
(seeds 1..K, mean), and whether the goal holds: the same held-out CD within 2 % with at most half
the engine-seconds.

    .venv/bin/python benchmarks/bench_multi_fidelity.py                 # both samplers, 11x15 mesh
    .venv/bin/python benchmarks/bench_multi_fidelity.py --quick         # TPE only, 6x8, 3 seeds
    .venv/bin/python benchmarks/bench_multi_fidelity.py --quick --fidelities coarse,prune
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import tempfile
import time

from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.identify.spec import AUTO, IdentifySpec
from cloth_bench_ros.identify.study import identify, TRIALS_FILE
from cloth_bench_ros.paths import bundled_bag
import numpy as np

GOAL_CD, GOAL_COST = 0.02, 0.5


def held_out(engine: str, bag: str, params: dict, seeds: int, grid: tuple | None) -> float:
    """Return the mean CD of `params` on seeds 1..seeds (the identification fitted seed 0)."""
    values = [
        evaluate(
            Trial(engine, 'towel', 'dynamic', bag, tuple(sorted(params.items())), seed=s,
                  grid=grid)
        )['value']
        for s in range(1, seeds + 1)
    ]
    return float(np.mean(values))


def one(engine: str, fidelity: str, args: argparse.Namespace, root: Path) -> dict:
    """Identify `engine` at `fidelity`; return its engine-seconds, trials and held-out CD."""
    bag = bundled_bag('towel', 'dynamic')
    out = root / f'{engine}_{fidelity}'
    spec = IdentifySpec(
        engine, 'towel', 'dynamic', bag, out, args.sampler, AUTO, grid=args.grid,
        validate_seeds=0, fidelity=fidelity,
    )
    start = time.perf_counter()
    outcome = identify(spec, workers=args.workers, progress=False)
    rows = [json.loads(line) for line in (out / TRIALS_FILE).read_text().splitlines() if line]
    s = outcome.summary
    return {
        'engine_s': float(sum(r.get('cpu_s', 0.0) for r in rows)),
        'trials': len(rows),
        'pruned': sum(r['status'] == 'pruned' for r in rows),
        'fitted': s['value'],
        'held_out': held_out(engine, str(bag), s['params'], args.seeds, args.grid),
        'wall_s': time.perf_counter() - start,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--engines', default='mujoco,bullet')
    parser.add_argument('--sampler', default='both', help='as identify --sampler (default both)')
    parser.add_argument('--grid', default=None, help="engine mesh NXxNZ (default the engine's)")
    parser.add_argument('--seeds', type=int, default=5, help='held-out seeds 1..N (default 5)')
    parser.add_argument('--workers', type=int, default=2)
    parser.add_argument('--fidelities', default='coarse', help='multi-fidelity rungs to compare')
    parser.add_argument('--quick', action='store_true', help='--sampler tpe --grid 6x8 --seeds 3')
    args = parser.parse_args()
    if args.quick:
        args.sampler, args.grid, args.seeds = 'tpe', args.grid or '6x8', 3
    args.grid = tuple(int(v) for v in args.grid.split('x')) if args.grid else None
    fidelities = [f for f in args.fidelities.split(',') if f != 'full']
    print(f'towel fling, --trials auto, sampler {args.sampler}, mesh {args.grid or "default"},'
          f' held-out seeds 1-{args.seeds}, {args.workers} workers')
    with tempfile.TemporaryDirectory() as tmp:
        for engine in args.engines.split(','):
            runs = {f: one(engine, f, args, Path(tmp)) for f in ['full', *fidelities]}
            for name, r in runs.items():
                print(f'{engine:<7} {name:<6} {r["engine_s"]:7.1f} engine-s,'
                      f' {r["trials"]:3d} trials ({r["pruned"]} pruned), fitted CD'
                      f' {r["fitted"]:.5f} m, held-out CD {r["held_out"]:.5f} m,'
                      f' wall {r["wall_s"]:.0f} s', flush=True)
            full = runs['full']
            for name in fidelities:
                cost = runs[name]['engine_s'] / full['engine_s']
                change = runs[name]['held_out'] / full['held_out'] - 1
                holds = cost <= GOAL_COST and change <= GOAL_CD
                print(f'{engine:<7} {name}/full: {cost:.0%} of the engine-seconds, held-out CD'
                      f' {change:+.1%}: goal (<= {GOAL_COST:.0%}, within {GOAL_CD:.0%})'
                      f' {"holds" if holds else "NOT met"}', flush=True)


if __name__ == '__main__':
    main()
