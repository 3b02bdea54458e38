"""
How much the way the start of the motion is found moves each engine's CD.

A plain recording of the bundled towel fling (its clouds with sensor noise, after a second of the
cloth hanging still) has its start found three ways: the recorded gripper targets (exact here),
the engine-free onset fitted in the clouds (data.trials: the default of `run`, `identify` and
`rank` without targets), and the search against a MuJoCo simulation (`--align simulation`). Each
start cuts the trial that every engine (preset, seed 0) is then scored on; the script prints each
start's error and each engine's CD with its change against the true start.

    .venv/bin/python benchmarks/bench_alignment_choice.py [--grid 6x8] [--noise 0.002]
"""

from __future__ import annotations

import argparse
from pathlib import Path
import tempfile

from cloth_bench_ros.core.scene import ClothGrid, REAL_FPS
from cloth_bench_ros.data import BagReader, BagWriter, CLOUD_TOPIC, TrialInfo
from cloth_bench_ros.data.alignment import reference_motion, search_start
from cloth_bench_ros.data.trials import split_clouds
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.paths import bundled_bag
import numpy as np

ENTRANTS = (('mujoco', ()), ('bullet', ()), ('newton', (('model', 'xpbd'),)))
BASE_NS = 1_700_000_000_000_000_000


def recording(noise: float, rest_s: float = 1.0) -> tuple[list[int], list[np.ndarray], int]:
    """Return stamps, clouds and the true start (ns) of a plain recording of the towel fling."""
    rng = np.random.default_rng(0)
    reader = BagReader(bundled_bag('towel', 'dynamic'))
    frames = list(reader.clouds())
    period = frames[1][0] - frames[0][0]
    rest = int(round(rest_s * 1e9 / period))
    clouds = [frames[0][1]] * rest + [p for _, p in frames]
    stamps = [BASE_NS + k * period for k in range(len(clouds))]
    noisy = [c + rng.normal(0, noise, c.shape) for c in clouds]
    return stamps, noisy, BASE_NS + rest * period


def trial_bag(path: Path, stamps: list[int], clouds: list[np.ndarray], start: int) -> str:
    """Write the frames from `start` on as a trial of the project's layout."""
    cop = BagReader(bundled_bag('towel', 'dynamic')).trial.change_of_phase_frame
    info = TrialInfo('towel', 0, 'dynamic', cop, 'bench_alignment_choice', fps=REAL_FPS)
    with BagWriter(path, info) as writer:
        for s, c in zip(stamps, clouds):
            if s >= start:
                writer.write_cloud(CLOUD_TOPIC, s - start, c)
    return str(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--grid', default='6x8', help='engine mesh NXxNZ (default 6x8)')
    parser.add_argument('--noise', type=float, default=0.002, help='sensor noise, m')
    args = parser.parse_args()
    grid = tuple(int(v) for v in args.grid.split('x'))
    stamps, clouds, true_ns = recording(args.noise)
    onset = split_clouds(stamps, clouds, 'dynamic').usable[0].start
    engine = make_engine('mujoco', 100.0, load_preset('mujoco', 'towel', 'dynamic'),
                         ClothGrid(*grid))
    t_ref, states = reference_motion(engine, 'dynamic', 100.0, 1.0)
    engine.close()
    searched = search_start(stamps, clouds, t_ref, states)
    starts = {'targets (true)': true_ns, 'onset in the clouds': onset.bag_ns,
              'MuJoCo search': searched.bag_ns}
    with tempfile.TemporaryDirectory() as tmp:
        bags = {m: trial_bag(Path(tmp) / f'b{i}', stamps, clouds, s)
                for i, (m, s) in enumerate(starts.items())}
        print(f'{"start found by":<22} {"error ms":>9} ' + ' '.join(
            f'{e + (":" + dict(p)["model"] if p else ""):>22}' for e, p in ENTRANTS))
        truth = {}
        for method, bag in bags.items():
            row = []
            for engine_name, params in ENTRANTS:
                cd = evaluate(Trial(engine_name, 'towel', 'dynamic', bag, params, grid=grid))['CD']
                truth.setdefault(engine_name, cd)
                change = (cd - truth[engine_name]) / truth[engine_name]
                row.append(f'{cd:.5f} ({change:+.1%})')
            error_ms = (starts[method] - true_ns) / 1e6
            print(f'{method:<22} {error_ms:>9.1f} ' + ' '.join(f'{r:>22}' for r in row))


if __name__ == '__main__':
    main()
