"""
The whole `cloth-bench rank` command on three camera-like recordings, timed.

The recordings are those of the rank tests, written by rosbags (not by the project's writer):
one MCAP bag of one towel fling, one sqlite3 bag of one, one MCAP bag of three with rest between
them; five trials, each a noisy camera-like copy of the bundled fling. The command runs as a user
types it (default entrants MuJoCo, PyBullet and Newton XPBD, `--trials auto`, TPE,
leave-one-trial-out, 3 held-out seeds, rates 10/100/1000 Hz) on `--workers` local processes; the
script prints the wall time against the goal (30 min on two cores), the process tree's CPU time,
the ranking with its intervals, diverged runs and paired differences, and the floor.

    .venv/bin/python benchmarks/bench_rank.py                      # the full command (long)
    .venv/bin/python benchmarks/bench_rank.py --fidelity coarse    # multi-fidelity identification
    .venv/bin/python benchmarks/bench_rank.py --quick              # a tiny budget: a smoke check
    .venv/bin/python benchmarks/bench_rank.py --keep DIR           # recordings and output kept
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
import resource
import sys
import tempfile
import time

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))  # the tests' recorder

from camera_recording import CAMERA_TOPIC, make_rank_recordings  # noqa: E402
from cloth_bench_ros import cli  # noqa: E402
from cloth_bench_ros.paths import bundled_bag  # noqa: E402

GOAL_S = 30 * 60
QUICK = ['--trials', '2', '--sampler', 'tpe', '--seeds', '1', '--grid', '6x8',
         '--recommend-rate', '100', '--max-frames', '6']


def recordings(root: Path) -> Path:
    """Write the three recordings, five trials, in a folder under root; return the folder."""
    folder = root / 'recordings'
    if folder.is_dir():
        return folder
    return make_rank_recordings(bundled_bag('towel', 'dynamic'), folder)


def cpu_seconds() -> float:
    """Return this process's and its finished children's user + system time."""
    own, children = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                     resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def summary(out: Path) -> list[str]:
    """Return the lines that answer: per group, the ranking with intervals and the floor."""
    result = json.loads((out / 'rank.json').read_text())
    lines = [f'trials: {len(result["trials"])}']
    for group, answer in result['answer'].items():
        floor = answer.get('floor') or {}
        low, mean, high = (floor.get(k, float('nan')) for k in ('min', 'mean', 'max'))
        lines.append(f'{group}: floor {mean:.4f} m [{low:.4f}, {high:.4f}]')
        boot = answer.get('bootstrap')
        if boot:
            lines.append(f'  paired bootstrap: {boot["trials"]} held-out trials x'
                         f' {boot["seeds_per_trial"]} seeds, {boot["replicates"]} replicates'
                         f' (seed {boot["seed"]})')
        for r in answer['ranking']:
            lines.append(f'  {r["name"]:<14} {_m(r["mean"])} m [{_m(r["low"])}, {_m(r["high"])}]'
                         f' n={r["n"]} diverged {r.get("diverged", "-")}/{r.get("runs", "-")}'
                         f' P(rank) {r["p_rank"]:.2f}')
        for d in answer.get('differences', []):
            lines.append(f'  {d["behind"]} - {d["ahead"]}: {_m(d["mean"], "+")} m'
                         f' [{_m(d["low"], "+")}, {_m(d["high"], "+")}] over {d["paired"]}'
                         f' paired runs ({d["decided_by"]}'
                         f'{", significant" if d["significant"] else ", not told apart"})')
        lines.append(f'  {answer["significance"]}')
    lines.extend(identification_costs(out))
    return lines


def _m(value: float | None, sign: str = '') -> str:
    return '-' if value is None else f'{value:{sign}.4f}'


def identification_costs(out: Path) -> list[str]:
    """Return per group and engine: trials per fold, simulations run and reused, engine-min."""
    lines = []
    for engine in sorted(out.glob('identify/*/*')):
        trials, run, reused, cpu = [], 0, 0, 0.0
        for fold in sorted(engine.glob('fold*')):
            summary = json.loads((fold / 'identification.json').read_text())
            trials.append('+'.join(str(s['trials']) for s in summary['per_sampler'].values()))
            shared = summary.get('shared_simulations', {})
            run, reused = run + shared.get('run', 0), reused + shared.get('reused', 0)
            for line in (fold / 'trials.jsonl').read_text().splitlines():
                cpu += json.loads(line).get('cpu_s') or 0.0
        lines.append(f'{engine.parent.name} {engine.name}: trials per fold {", ".join(trials)}; '
                     f'simulations run {run}, reused {reused}; {cpu / 60:.1f} engine-min')
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--workers', type=int, default=2, help='local worker processes')
    parser.add_argument('--fidelity', default='full', help='full, prune or coarse')
    parser.add_argument('--quick', action='store_true', help='a tiny budget (smoke check)')
    parser.add_argument('--keep', type=Path, help='write recordings and output here (resumable)')
    args, extra = parser.parse_known_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        folder, out = recordings(root), root / 'rank'
        argv = ['rank', str(folder), '--topic', CAMERA_TOPIC, '--output', str(out),
                '--workers', str(args.workers), '--fidelity', args.fidelity, '--no-progress',
                *(QUICK if args.quick else []), *extra]
        print('cloth-bench ' + ' '.join(argv), flush=True)
        start, cpu = time.perf_counter(), cpu_seconds()
        code = cli.main(argv)
        wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
        if code != 0:
            print(f'rank exited {code} after {wall:.0f} s')
            return code
        print('\n'.join(summary(out)))
        verdict = 'meets' if wall <= GOAL_S else 'does NOT meet'
        budget = ' (quick budget)' if args.quick else ''
        print(f'wall {wall / 60:.1f} min, CPU {cpu / 60:.1f} core-min ({args.workers} workers): '
              f'{verdict} the goal of {GOAL_S / 60:.0f} min{budget}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
