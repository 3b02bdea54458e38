"""
The fast settle against the full one (`--settle`): the start state, the held-out CD, the cost.

For every engine and model (MuJoCo shell, PyBullet mass-spring, Newton XPBD and VBD) and every
parameter set (the towel presets of both tasks and the identified sets in config/presets/), one
simulation per settle and seed on the default 11 x 15 grid at 100 Hz. Printed per set:

- `moving`: how far the cloth still moves at the end of the full settle, the largest vertex
  travel over its last step (mm) and over its last 0.1 s;
- `start d`: the largest vertex distance between the two settles' states at the start of the
  quintic part (mm; the acceptance asks for at most 1), and `seed d`, the same distance between
  seeds 0 and 1 of the full settle (the protocol's own spread of that state);
- `CD full`, `CD fast`, `dCD`: the mean held-out CD (seeds 1..N, as `identify` validates) of
  each settle on the set's bag (the identified sets), and its change (%; the acceptance asks for
  at most 0.5); `se`: the standard error of the full settle's mean over those seeds (%), the
  seeds' own noise;
- engine-seconds (the sum of the steps' CPU times, which the load of other processes disturbs
  less than their wall times) of the settle and of a whole simulation (every target of the run),
  full -> fast, and `steps`, the engine steps of the fast settle (the full one takes 299) and
  of the whole fast simulation over the full one's (%).

    .venv/bin/python benchmarks/bench_settle.py [--engines mujoco bullet newton]
        [--seeds 3] [--sets preset identified identified-newton-vbd] [--no-cd]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import time

from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.engines.settle import Settler, SETTLES
from cloth_bench_ros.identify.objective import evaluate, Trial
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RATE_HZ = 100.0
MODELS = {'mujoco': [None], 'bullet': [None], 'newton': ['xpbd', 'vbd']}
SETS = ('preset', 'identified', 'identified-newton-vbd')
BAGS = {'identified-newton-vbd': '{primitive}_newton_vbd'}  # the references each set was fit to


def simulate(engine: str, params: dict, primitive: str, settle: str, seed: int) -> dict:
    """Return one run's state at the start of the quintic part and its engine-seconds."""
    targets = full_targets(primitive, RATE_HZ)
    q = targets.quintic_index
    sim = make_engine(engine, RATE_HZ, params)
    settler = Settler(sim, targets, settle)
    states = [sim.start(seed, targets.left[0], targets.right[0])]
    times = np.zeros(len(targets))
    for k in range(1, len(targets)):
        start = time.process_time()
        vertices = settler.step(k, targets.left[k], targets.right[k])
        times[k] = time.process_time() - start
        if k <= q:
            states.append(vertices.copy())
    sim.close()
    return {
        'start': states[q],
        'last_step': float(np.linalg.norm(states[q] - states[q - 1], axis=1).max()),
        'last_10': float(np.linalg.norm(states[q] - states[q - 10], axis=1).max()),
        'settle_s': float(times[1:q].sum()),
        'whole_s': float(times.sum()),
        'steps': sim.steps,
        'settle_steps': sim.steps - (len(targets) - q),
        'diverged': sim.divergence,
    }


def held_out_cd(engine: str, params: dict, primitive: str, bag: Path, settle: str,
                seeds: int) -> list[float]:
    """Return the CD of seeds 1..`seeds` on `bag`, as `identify` validates a set."""
    values = []
    for seed in range(1, seeds + 1):
        out = evaluate(Trial(engine, 'towel', primitive, str(bag), tuple(sorted(params.items())),
                             seed=seed, settle=settle))
        values.append(out['CD'] if out['status'] == 'ok' else np.nan)
    return values


def parameter_sets(engines: list[str], sets: list[str]) -> list[tuple[str, str, str, dict, Path]]:
    """Return (engine, label, primitive, parameters, bag) of every set the repository holds."""
    out = []
    for engine in engines:
        for model in MODELS[engine]:
            for primitive in ('dynamic', 'quasi_static'):
                for name in sets:
                    directory = None if name == 'preset' else ROOT / 'config' / 'presets' / name
                    try:
                        params = load_preset(engine, 'towel', primitive, directory, model)
                    except EngineError:  # a set without this model's entry
                        continue
                    if model:
                        params['model'] = model
                    bag = BAGS.get(name, '{primitive}').format(primitive=f'towel_{primitive}')
                    label = f'{engine}/{params.get("model", "")} {name} {primitive}'
                    out.append((engine, label, primitive, params, ROOT / 'bags' / bag))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--engines', nargs='+', default=list(MODELS), choices=list(MODELS))
    parser.add_argument('--sets', nargs='+', default=list(SETS), choices=SETS)
    parser.add_argument('--seeds', type=int, default=3, help='held-out seeds of the CD (1..N)')
    parser.add_argument('--no-cd', action='store_true', help='skip the held-out CD')
    args = parser.parse_args()
    print(f'{"engine/model set task":42s} {"moving mm":>13s} {"start d":>7s} {"seed d":>6s}'
          f' {"CD full":>8s} {"CD fast":>8s} {"dCD %":>6s} {"se %":>5s}'
          f' {"settle s full->fast":>20s}'
          f' {"whole s full->fast":>19s} {"steps":>5s}')
    totals = {s: [0.0, 0.0] for s in SETTLES}
    for engine, label, primitive, params, bag in parameter_sets(args.engines, args.sets):
        full, fast = (simulate(engine, params, primitive, s, 0) for s in SETTLES)
        other = simulate(engine, params, primitive, 'full', 1)
        start_d = np.linalg.norm(fast['start'] - full['start'], axis=1).max() * 1e3
        seed_d = np.linalg.norm(other['start'] - full['start'], axis=1).max() * 1e3
        cds = [[np.nan], [np.nan]]
        if not args.no_cd and bag.exists() and 'identified' in label:
            cds = [held_out_cd(engine, params, primitive, bag, s, args.seeds) for s in SETTLES]
        cd = [float(np.mean(c)) for c in cds]
        change = 100 * (cd[1] - cd[0]) / cd[0]
        se = 100 * np.std(cds[0], ddof=1) / np.sqrt(len(cds[0])) / cd[0] if len(cds[0]) > 1 \
            else np.nan
        for s, run in (('full', full), ('fast', fast)):
            totals[s][0] += run['settle_s']
            totals[s][1] += run['whole_s']
        steps = fast['settle_steps']
        whole = 100 * fast['steps'] / full['steps']
        flag = ' diverged' if full['diverged'] or fast['diverged'] else ''
        print(f'{label:42s} {full["last_step"] * 1e3:5.2f} {full["last_10"] * 1e3:6.2f}'
              f' {start_d:7.2f} {seed_d:6.1f} {cd[0]:8.5f} {cd[1]:8.5f} {change:+6.2f} {se:5.2f}'
              f' {full["settle_s"]:8.3f} -> {fast["settle_s"]:7.3f}'
              f' {full["whole_s"]:8.3f} -> {fast["whole_s"]:7.3f} {steps:5d} {whole:4.0f} %{flag}',
              flush=True)
    for s in SETTLES:
        print(f'total {s}: settle {totals[s][0]:.2f} engine-s, whole simulations '
              f'{totals[s][1]:.2f} engine-s')


if __name__ == '__main__':
    main()
