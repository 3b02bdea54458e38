"""
Every cloth-bench command's output before and after a change: record each, compare two records.

`record DIR` runs a fixed list of commands (every subcommand at least once, on the bundled bags
and two small recordings written by the tests' helpers, with small settings: a 6x8 grid, one rate,
few trials and seeds, one worker, lockstep on the CPU) and keeps per command its argv, exit code,
stdout, stderr and every file it wrote. `compare OLD NEW` prints one line per command, `same` or
`DIFFERENT:` with the first differing lines or JSON paths, and exits 1 if any differ. Only what
legitimately varies run to run is normalised (compare_outputs.py: the record's own paths and
temporary folders, dates, wall-clock and step timings, progress bars); every number of the physics
and metrics must match exactly. Lines saying "is deprecated, use" (a renamed flag's old spelling)
are listed apart, not as a difference; a changed `--help` text is listed, not counted. `synth`
and `converge` take minutes at their smallest: only their errors are in the list, the runs
themselves with --long.

The commands run the cloth_bench_ros that this Python imports: set PYTHONPATH to the checkout
under test (record.json and the last line of `record` name the package and its commit).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/compare_commands.py record /tmp/before  # 3-6 min
    git checkout my-branch
    PYTHONPATH=$PWD .venv/bin/python benchmarks/compare_commands.py record /tmp/after
    .venv/bin/python benchmarks/compare_commands.py compare /tmp/before /tmp/after
    .venv/bin/python benchmarks/compare_commands.py list                 # the commands
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import shutil
import subprocess
import sys
import time
from typing import Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))  # its normaliser, next to it
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))  # the tests' recorder

import cloth_bench_ros  # noqa: E402
from compare_outputs import compare_records  # noqa: E402
from own_motion_recording import write_recording  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO / 'bags'
SMALL = ['--grid', '6x8']
OWN = ['--bag', '{record}/_inputs/own_motion', '--topic', '/points',
       '--gripper-frames', 'left_gripper,right_gripper']
ONE_WORKER = ['--workers', '1', '--no-progress']


def bag(name: str) -> str:
    """Return a bundled bag's directory."""
    return str(BAGS / name)


# name -> argv after `cloth-bench`; {out} is the command's own output folder, {record} the record
# (for what an earlier command wrote). Names starting help_ are help texts: listed when changed.
# A verdict on measured step times (rank's recommendation, whether a deadline is met) follows the
# machine's load: compare_outputs masks it with the timings.
COMMANDS: dict[str, list[str]] = {
    'engines': ['engines'],
    'trajectory_dynamic': ['trajectory', '--primitive', 'dynamic', '--rate', '100'],
    'trajectory_quasi_static': ['trajectory', '--primitive', 'quasi_static', '--rate', '30'],
    'bag_info': ['bag', 'info', bag('towel_dynamic')],
    'bag_rewrite': ['bag', 'rewrite', bag('chequered_dynamic'), '{out}/rewritten',
                    '--change-of-phase-frame', 'detected'],
    'motion': ['motion', *OWN, '--table-z', '0.65', '--output', '{out}/task.yaml'],
    'run': ['run', '--engine', 'mujoco', '--engine', 'bullet', *SMALL, '--output', '{out}'],
    'run_newton': ['run', '--cloth', 'linen', '--engine', 'newton', '--device', 'cpu', *SMALL,
                   '--seed', '3', '--output', '{out}'],
    'run_own_recording': ['run', *OWN, '--engine', 'mujoco', '--engine', 'bullet', *SMALL,
                          '--record-comparison', '{out}/comparison', '--output', '{out}/report'],
    'run_task_file': [
        'run', '--task', '{record}/motion/work/out/task.yaml', *OWN[:4], '--motion', 'task',
        '--engine', 'mujoco', *SMALL, '--clean', 'on', '--voxel', '0.01',
        '--change-of-phase-frame', '80', '--set', 'mujoco.damping=0.02',
        '--cloth-size', '0.5,0.65', '--cloth-mass', '0.1', '--output', '{out}'],
    'sweep': ['sweep', '--engine', 'mujoco', '--engine', 'bullet', '--rate', '100',
              '--cloth', 'towel', '--primitive', 'dynamic', '--seeds', '2', *SMALL,
              *ONE_WORKER, '--output', '{out}'],
    'sweep_settings': ['sweep', '--mode', 'settings', '--engine', 'mujoco', '--axis',
                       'grid=6x8,4x5', '--rate', '10', '--seeds', '1', *ONE_WORKER, '--output',
                       '{out}'],
    'sweep_dry_run': ['sweep', '--dry-run', '--output', '{out}'],
    'report': ['report', '{record}/sweep/work/out', '--output', '{out}'],
    'stress': ['stress', '--engine', 'mujoco', '--engine', 'bullet', '--case', 'fling_10hz',
               '--case', 'gripper_jump', *ONE_WORKER, '--output', '{out}'],
    'cross_reference': ['cross-reference', '--primitive', 'dynamic', '--seeds', '1',
                        *ONE_WORKER, '--output', '{out}'],
    'identify': ['identify', '--engine', 'mujoco', '--sampler', 'tpe', '--trials', '4', *SMALL,
                 '--max-frames', '20', '--validate-seeds', '1', *ONE_WORKER, '--output', '{out}'],
    'rank': ['rank', bag('towel_dynamic'), bag('towel_dynamic_newton_vbd'), '--engine', 'mujoco',
             '--engine', 'bullet', '--trials', '2', '--sampler', 'tpe', '--seeds', '1', *SMALL,
             '--rates', '10', '--max-frames', '6', *ONE_WORKER, '--output', '{out}'],
    'hil': ['hil', '--engine', 'mujoco', '--rate', '10', *SMALL, '--layout', 'none',
            '--in-process', '--duration', '1', '--output', '{out}'],
    'hil_export_recommended': ['hil', '--export-recommended', '{out}.yaml',
                               '--settings', '{record}/sweep_settings/work/out'],
    'import': ['import', '{record}/_inputs/dataset', '--out', '{out}', '--quiet'],
    'synth_bad_rate': ['synth', '--out', '{out}/towel_dynamic', '--rate', '1000', '--quiet'],
    'converge_bad_levels': ['converge', '--levels', '0', '--output', '{out}'],
    'error_bad_rate': ['run', '--rate', '0'],
    'error_missing_bag': ['run', '--bag', '{record}/_inputs/no_such_bag', '--output', '{out}'],
    'error_bad_rates_list': ['rank', bag('towel_dynamic'), '--rates', '10,abc'],
}
# minutes each, recorded with --long only: both simulate the 31x43 reference (no smaller setting)
LONG: dict[str, list[str]] = {
    'synth': ['synth', '--out', '{out}/towel_dynamic', '--seed', '1', '--quiet'],
    'converge': ['converge', '--axis', 'iterations', '--levels', '1', '--duration', '0.5',
                 *ONE_WORKER, '--output', '{out}'],
}
for _sub in ('run', 'trajectory', 'motion', 'engines', 'sweep', 'report', 'stress',
             'cross-reference', 'identify', 'rank', 'hil', 'import', 'synth', 'converge', 'bag'):
    COMMANDS[f'help_{_sub.replace("-", "_")}'] = [_sub, '--help']


def write_inputs(inputs: Path) -> None:
    """Write the recordings the commands read besides the bundled bags (afresh each record)."""
    write_dataset(inputs / 'dataset')
    write_recording(inputs / 'own_motion', frame='base_link')


def write_dataset(root: Path) -> None:
    """Write a tiny published-dataset tree for `import`: one trial of five ASCII PLY frames."""
    cloud = root / 'cotton_rag_0' / 'dynamic' / 'cloud'
    cloud.mkdir(parents=True, exist_ok=True)
    for frame in range(5):
        points = [(0.01 * i - 0.25, 0.002 * frame, 0.7 - 0.013 * (i % 7)) for i in range(60)]
        header = f'ply\nformat ascii 1.0\nelement vertex {len(points)}\n' \
            'property float x\nproperty float y\nproperty float z\nend_header\n'
        rows = ''.join(f'{x:.4f} {y:.4f} {z:.4f}\n' for x, y, z in points)
        (cloud / f'{frame:05d}.ply').write_text(header + rows)


def run_one(name: str, argv: list[str], record: Path, timeout_s: float) -> dict:
    """Run one command in its own work folder under the record; keep its streams and files."""
    folder = record / name
    shutil.rmtree(folder, ignore_errors=True)
    work = folder / 'work'
    work.mkdir(parents=True)
    argv = [a.replace('{out}', str(work / 'out')).replace('{record}', str(record)) for a in argv]
    env = dict(os.environ, COLUMNS='100', PYTHONHASHSEED='0')
    start = time.monotonic()
    try:
        done = subprocess.run([sys.executable, '-m', 'cloth_bench_ros.cli', *argv], cwd=work,
                              env=env, capture_output=True, text=True, timeout=timeout_s)
        code, stdout, stderr = done.returncode, done.stdout, done.stderr
    except subprocess.TimeoutExpired as timeout:
        code, stdout, stderr = 124, _text(timeout.stdout), _text(timeout.stderr)
    wall_s = time.monotonic() - start
    (folder / 'stdout.txt').write_text(stdout)
    (folder / 'stderr.txt').write_text(stderr)
    meta = {'name': name, 'argv': argv, 'exit_code': code, 'wall_s': round(wall_s, 1)}
    (folder / 'command.json').write_text(json.dumps(meta, indent=1) + '\n')
    return meta


def _text(stream: bytes | str | None) -> str:
    return stream.decode(errors='replace') if isinstance(stream, bytes) else (stream or '')


def record(record_dir: Path, names: Sequence[str], timeout_s: float) -> int:
    """Run the commands into record_dir; print each one's exit code and wall time."""
    record_dir = record_dir.resolve()
    record_dir.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(record_dir / '_inputs', ignore_errors=True)
    write_inputs(record_dir / '_inputs')
    commit = subprocess.run(['git', '-C', str(REPO), 'describe', '--always', '--dirty'],
                            capture_output=True, text=True).stdout.strip()
    about = {'record': str(record_dir), 'repo': str(REPO), 'commit': commit,
             'package': str(Path(cloth_bench_ros.__file__).parent), 'python': sys.executable,
             'date': time.strftime('%Y-%m-%d %H:%M:%S'), 'commands': list(names)}
    (record_dir / 'record.json').write_text(json.dumps(about, indent=1) + '\n')
    start = time.monotonic()
    for name in names:
        meta = run_one(name, {**COMMANDS, **LONG}[name], record_dir, timeout_s)
        print(f'{name:28s} exit {meta["exit_code"]:3d}  {meta["wall_s"]:7.1f} s', flush=True)
    print(f'recorded {len(names)} commands of {about["package"]} ({commit}) into {record_dir} in '
          f'{time.monotonic() - start:.0f} s')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Record, compare or list."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    sub = parser.add_subparsers(dest='action', required=True)
    rec = sub.add_parser('record', help='run every command into DIR')
    rec.add_argument('dir', type=Path)
    rec.add_argument('--only', action='append', choices=sorted({**COMMANDS, **LONG}),
                     metavar='NAME', help='only this command (repeat; default all, in order)')
    rec.add_argument('--long', action='store_true', help=f'also {", ".join(LONG)} (minutes)')
    rec.add_argument('--timeout', type=float, default=300.0, help='seconds per command')
    cmp = sub.add_parser('compare', help='compare two records; exit 1 if any command differs')
    cmp.add_argument('old', type=Path)
    cmp.add_argument('new', type=Path)
    sub.add_parser('list', help='print the commands')
    args = parser.parse_args(argv)
    if args.action == 'list':
        for name, command in {**COMMANDS, **LONG}.items():
            print(f'{name:28s} cloth-bench {" ".join(command)}'
                  + ('  (--long)' if name in LONG else ''))
        return 0
    if args.action == 'record':
        names = args.only or [*COMMANDS, *(LONG if args.long else ())]
        return record(args.dir, names, args.timeout)
    return compare_records(args.old, args.new)


if __name__ == '__main__':
    sys.exit(main())
