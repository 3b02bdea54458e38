"""`cloth-bench rank` as it runs: the trials, the study, the answer (parser: cli/rank.py)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from cloth_bench_ros.cli import bag_inputs, common
from cloth_bench_ros.cli.common import UserError
from cloth_bench_ros.cli.rank import RESULT_FILE
from cloth_bench_ros.cli.run_command import recordings_motions
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.rank import study, trials
from cloth_bench_ros.rank.answer import rank_answer
from cloth_bench_ros.report.rank import rank_lines, rank_table
from cloth_bench_ros.studies.cloth import cloth_choice
from cloth_bench_ros.studies.errors import StudyInterrupted


def cmd_rank(args: argparse.Namespace) -> int:
    """Run the protocol, print the table and its sentences, write rank.json."""
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
    replay = bag_inputs.replay_options(args)
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
