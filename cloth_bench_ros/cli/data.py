"""`cloth-bench import`, `synth` and `bag`: making and inspecting the bags runs score against."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.cli import common


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register import, synth, converge and bag (info, rewrite)."""
    imp = sub.add_parser(
        'import', help='turn the published dataset (PLY/PCD per frame) into one bag per trial'
    )
    imp.add_argument(
        'root', help='dataset root: <root>/<cloth>_rag_<trial>/<primitive>/cloud/<NNNNN>.ply|.pcd'
    )
    imp.add_argument('--out', required=True, help='directory for the bags')
    imp.add_argument(
        '--transform',
        help='4x4 matrix into the simulation frame (text file of 16 numbers, or .npy)',
    )
    imp.add_argument('--overwrite', action='store_true', help='replace bags that exist')
    imp.add_argument(
        '--clean',
        action='store_true',
        help=(
            'crop to the workspace, remove the table plane and outliers (core.cleaning) before'
            ' writing'
        ),
    )
    common.add_option(imp, 'voxel', help='with --clean: voxel size (0: off)')
    imp.add_argument('--quiet', action='store_true', help='no progress bar')
    imp.set_defaults(func=cmd_import)

    synth = sub.add_parser(
        'synth',
        parents=[common.scene_options()],
        help='make a synthetic reference bag (reference simulation seen by a virtual Kinect)',
    )
    synth.add_argument('--out', help='bag directory (default <cloth>_<primitive>)')
    common.add_option(synth, 'seed', help='sensor noise and reference seed')
    synth.add_argument(
        '--reference',
        default='mujoco',
        choices=('mujoco', 'newton-vbd'),
        help=(
            'reference model: mujoco (config/synth.yaml, default) or newton-vbd '
            '(config/synth_newton_vbd.yaml); default bag name <cloth>_<primitive>[_newton_vbd]'
        ),
    )
    synth.add_argument(
        '--rate',
        type=common.number(validation.positive, '--rate'),
        metavar='HZ',
        help="the reference's step rate, a multiple of 30 (default: the reference file's)",
    )
    synth.add_argument('--overwrite', action='store_true', help='replace the bag if it exists')
    synth.add_argument('--quiet', action='store_true', help='no progress bar')
    common.device_option(synth, with_set=False)
    synth.set_defaults(func=cmd_synth)

    converge = sub.add_parser(
        'converge',
        parents=[common.scene_options(), common.executor_options()],
        help="a synthetic reference's convergence in iterations, step rate and mesh resolution",
    )
    converge.add_argument(
        '--reference', default='mujoco', choices=('mujoco', 'newton-vbd'), help='default mujoco'
    )
    converge.add_argument(
        '--axis', action='append', choices=('iterations', 'rate', 'grid'),
        help='setting to refine (repeatable; default all three)',
    )
    converge.add_argument(
        '--levels', type=common.integer('--levels', 1), default=1,
        help='refinements per axis: iterations and rate x2 each, grid spacing /1.5 (default 1)',
    )
    converge.add_argument(
        '--duration', type=common.number(validation.positive, '--duration'), metavar='S',
        help='seconds of the quintic part (default: the whole trial)',
    )
    converge.add_argument(
        '--score',
        action='append',
        metavar='ENGINE',
        help="score this engine's preset (tested grid) against every run (repeatable)",
    )
    converge.add_argument(
        '--output', help='directory: one .npz per run (reused) and convergence.json'
        ' (default results/convergence/<reference>_<cloth>_<primitive>)',
    )
    common.device_option(converge, with_set=False)
    converge.set_defaults(func=cmd_converge)

    bag = sub.add_parser('bag', help='bag tools')
    bag_sub = bag.add_subparsers(dest='bag_command', required=True, parser_class=common.Parser)
    info = bag_sub.add_parser('info', help='describe a bag: topics, frames, trial metadata')
    info.add_argument('path')
    info.set_defaults(func=cmd_bag_info)
    rewrite = bag_sub.add_parser(
        'rewrite',
        help=(
            "copy a bag into the current writer's layout (rosbag2 Jazzy, "
            'metadata version 9, type hashes); messages and trial unchanged'
        ),
    )
    rewrite.add_argument('src', help='bag to read')
    rewrite.add_argument('dst', help='new bag directory (must not exist or be empty)')
    rewrite.add_argument(
        '--change-of-phase-frame',
        metavar='N|detected',
        type=_frame_or_detected,
        help=(
            'store this change-of-phase frame in the trial (dynamic task), or the first '
            'table contact found in the clouds'
        ),
    )
    rewrite.set_defaults(func=cmd_bag_rewrite)


def _frame_or_detected(text: str) -> int | str:
    return 'detected' if text == 'detected' else common.frame(text)


def cmd_import(args: argparse.Namespace) -> int:
    """Import the published dataset's per-frame clouds into one bag per trial."""
    from cloth_bench_ros.core.cleaning import scene_cleaning
    from cloth_bench_ros.data.importer import import_dataset

    transform = common.read_transform(args.transform) if args.transform else None
    bags = import_dataset(
        Path(args.root),
        Path(args.out),
        transform=transform,
        progress=not args.quiet,
        overwrite=args.overwrite,
        cleaning=scene_cleaning(voxel=args.voxel) if args.clean else None,
    )
    for bag in bags:
        print(bag)
    print(f'imported {len(bags)} trial(s) into {args.out}')
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    """Write a synthetic reference bag."""
    from cloth_bench_ros.data.synth import synth_command

    suffix = '' if args.reference == 'mujoco' else '_' + args.reference.replace('-', '_')
    out = Path(args.out) if args.out else Path(f'{args.cloth}_{args.primitive}{suffix}')
    bag = synth_command(
        args.cloth,
        args.primitive,
        out,
        seed=args.seed,
        overwrite=args.overwrite,
        progress=not args.quiet,
        reference=args.reference,
        rate_hz=args.rate,
        device=args.device,
    )
    print(f'synthetic bag written: {bag}')
    return 0


def cmd_converge(args: argparse.Namespace) -> int:
    """Run a reference's convergence study on the executor; print and save its table."""
    from cloth_bench_ros.safe_io import check_output_dir
    from cloth_bench_ros.studies import reference_convergence as rc
    from cloth_bench_ros.studies.dask_executor import open_client, run_tasks

    available = common.available_engines()
    for engine in args.score or []:
        if engine not in available:
            raise validation.InputError(
                f'--score: {engine!r} is not an available engine ({", ".join(available)})'
            )
    study = rc.ConvergenceStudy(
        args.reference,
        args.cloth,
        args.primitive,
        axes=tuple(args.axis or rc.AXES),
        levels=args.levels,
        duration=args.duration,
        scored=tuple(validation.unique(args.score or [], '--score')),
        device=args.device,
    )
    name = f'{args.reference.replace("-", "_")}_{args.cloth}_{args.primitive}'
    out = check_output_dir(args.output or f'results/convergence/{name}')
    runs = study.variants()
    print(f'cloth-bench converge: {len(runs)} runs of the {args.reference} reference -> {out}')
    with open_client(args.scheduler, args.workers) as client:
        study.run(out, lambda *a: run_tasks(client, *a))
    rows = study.rows()
    rc.save(rows, study, out / 'convergence.json')
    print(rc.format_rows(rows))
    return 0 if all(not r.get('error') for r in rows) else 1


def cmd_bag_info(args: argparse.Namespace) -> int:
    """Describe a bag: topics, frames, trial metadata."""
    from cloth_bench_ros.data import describe

    print(describe(Path(args.path)))
    return 0


def cmd_bag_rewrite(args: argparse.Namespace) -> int:
    """Copy a bag into the current writer's layout, checking the messages are unchanged."""
    from cloth_bench_ros.data import BagReader
    from cloth_bench_ros.data.bag_rewrite import rewrite_bag

    counts = rewrite_bag(Path(args.src), Path(args.dst), args.change_of_phase_frame)
    changed = ''
    if args.change_of_phase_frame is not None:
        with BagReader(Path(args.dst)) as rewritten:
            trial = rewritten.trial
        frame = trial.change_of_phase_frame if trial is not None else None
        changed = f'; change of phase set to frame {frame}'
    print(
        f'rewrote {args.src} -> {args.dst}: {sum(counts.values())} messages, unchanged'
        f' (checked){changed}'
    )
    return 0
