"""`cloth-bench rank`: which simulator for my cloth, from the user's own recordings."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cloth_bench_ros.cli import common
from cloth_bench_ros.cli.common import UserError
from cloth_bench_ros.cli.identify import TRIALS
from cloth_bench_ros.cli.run import recordings_motions
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.rank.answer import rank_answer
from cloth_bench_ros.report.rank import rank_lines, rank_table
from cloth_bench_ros.studies.cloth import cloth_choice
from cloth_bench_ros.studies.errors import StudyInterrupted

RESULT_FILE = 'rank.json'


def _entrant(text: str, label: str = '--engine') -> tuple[str, dict]:
    """--engine NAME or NAME:MODEL (newton:xpbd, newton:vbd)."""
    name, _, model = text.strip().partition(':')
    engine_class(name)  # EngineError, one line, for an unknown engine
    return name, ({'model': model} if model else {})


RANK_FLAGS: tuple[common.Flag, ...] = (
    'recordings',
    ('engines', {'validate': _entrant,
                 'help': 'engine[:model] (repeat; default mujoco, bullet, newton:xpbd)'}),
    TRIALS,
    'sampler',
    ('fidelity', {'help': 'identification: full (default), or prune, coarse: multi-fidelity, '
                  'as identify'}),
    'rank_seeds',
    ('rate_hz', {'help': 'simulator rate of identification and scoring'}),
    'rates',
    'grid',
    'metric',  # cd/hd: also the identification objective (else cd)
    'max_frames',
    'settle',
    ('output', {'help': 'directory (default results/rank)'}),
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register rank."""
    rank = sub.add_parser(
        'rank',
        parents=[common.scene_options(), common.executor_options()],
        help='rank the engines on your own recordings: identified, scored on held-out trials',
    )
    common.add_options(rank, RANK_FLAGS)
    common.add_renamed(rank, '--rates', '--recommend-rate', split=True)
    common.recording_options(rank)
    common.engine_override_option(rank, 'fixed on every entrant of that engine, not fitted')
    common.add_option(rank, 'cloth_size')
    common.add_option(rank, 'cloth_mass', help='total mass of the cloth, not fitted')
    common.add_option(rank, 'cloth_mesh')
    rank.set_defaults(func=cmd_rank)


def cmd_rank(args: argparse.Namespace) -> int:
    """Run the protocol, print the table and its sentences, write rank.json."""
    from cloth_bench_ros.rank import study, trials  # lazy: Optuna, Dask, engines, +1.6 s

    entrants = args.engine or list(study.DEFAULT_ENTRANTS)
    fixed = common.engine_overrides(args.set, sorted({e for e, _ in entrants}))
    size, mass = cloth_choice(args.cloth_size, args.cloth_mass, fixed)
    load_task(args.primitive, args.task)  # a bad task file: one line, before the work
    common.check_split_without_engine(args, 'rank')
    if args.trial:
        raise UserError('--trial: rank scores every usable trial of each recording; --trial '
                        'picks the one that run scores or identify fits')
    out = Path(args.output) if args.output else Path('results') / 'rank'
    bags = trials.recordings_of(args.recordings)
    tasks, motion_lines = recordings_motions(args, bags, out)
    # the split never simulates: its starts are fitted in the recordings (--align onset) or are
    # the recorded motions' first clouds
    replay = common.replay_options(args)
    spec = study.RankSpec(
        [str(b) for b in bags], out, entrants, replay, args.trials, args.sampler, args.seeds,
        args.rate, args.rates, args.grid, args.metric, args.max_frames, fixed, args.fidelity,
        size, mass, tasks=tasks, cloth_mesh=args.cloth_mesh or '',
        gripper_frames=args.gripper_frames or '', table_z=args.table_z, settle=args.settle,
    )
    print(f'cloth-bench rank: {", ".join(args.recordings)}; engines '
          f'{", ".join(e + (":" + o["model"] if o else "") for e, o in entrants)}; '
          f'{args.settle} settle; output {out}',
          flush=True)
    for line in motion_lines:
        print(line)
    try:
        raw = study.run_rank(spec, args.scheduler, args.workers, progress=not args.no_progress)
    except KeyboardInterrupt:
        raise StudyInterrupted(
            f'rank interrupted: every finished identification (journals under {out}/identify) '
            f'and cell ({out / study.CELLS_FILE}) is kept; run the same command again to resume'
        ) from None
    result = rank_answer(raw)
    print(rank_table(result).markdown())
    for line in rank_lines(result):
        print(line)
    path = out / RESULT_FILE
    path.write_text(json.dumps(result, indent=1, default=float, allow_nan=False))
    print(f'rank: {path}')
    if not result['answer']:
        raise UserError('rank: no group could be ranked')
    return 0
