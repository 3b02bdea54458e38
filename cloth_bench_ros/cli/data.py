"""`cloth-bench import`, `synth` and `bag`: making and inspecting the bags runs score against."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.cli import common
from cloth_bench_ros.safe_io import check_output_dir


IMPORT_FLAGS: tuple[common.Flag, ...] = (
    'root',
    ('output', {'help': 'directory for the bags (required)'}),
    ('transform', {'help': '4x4 matrix into the simulation frame (text file of 16 numbers, or '
                   '.npy)'}),
    ('overwrite', {'help': 'replace bags that exist'}),
    'import_clean',
    ('voxel', {'help': 'with --clean: voxel size (0: off)'}),
    'no_progress',
)
SYNTH_FLAGS: tuple[common.Flag, ...] = (
    ('output', {'help': 'bag directory (default <cloth>_<primitive>[_newton_vbd])'}),
    ('seed', {'help': 'sensor noise and reference seed'}),
    'reference',
    'synth_rate',
    ('overwrite', {'help': 'replace the bag if it exists'}),
    'no_progress',
)
CONVERGE_FLAGS: tuple[common.Flag, ...] = (
    ('reference', {'help': 'the reference model'}),
    'converge_axis',
    'levels',
    'converge_duration',
    'score',
    ('output', {'help': 'directory: one .npz per run (reused) and convergence.json (default '
                'results/convergence/<reference>_<cloth>_<primitive>)'}),
)
REWRITE_FLAGS: tuple[common.Flag, ...] = ('src', 'dst', 'rewrite_change_of_phase_frame')


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register import, synth, converge and bag (info, rewrite)."""
    imp = sub.add_parser(
        'import', help='turn the published dataset (PLY/PCD per frame) into one bag per trial'
    )
    common.add_options(imp, IMPORT_FLAGS)
    common.add_renamed(imp, '--out', '--output')
    common.add_renamed(imp, '--quiet', '--no-progress')
    imp.set_defaults(func=cmd_import)

    synth = sub.add_parser(
        'synth',
        parents=[common.scene_options()],
        help='make a synthetic reference bag (reference simulation seen by a virtual Kinect)',
    )
    common.add_options(synth, SYNTH_FLAGS)
    common.add_renamed(synth, '--out', '--output')
    common.add_renamed(synth, '--quiet', '--no-progress')
    common.device_option(synth, with_set=False)
    synth.set_defaults(func=cmd_synth)

    converge = sub.add_parser(
        'converge',
        parents=[common.scene_options(), common.executor_options()],
        help="a synthetic reference's convergence in iterations, step rate and mesh resolution",
    )
    common.add_options(converge, CONVERGE_FLAGS)
    common.device_option(converge, with_set=False)
    converge.set_defaults(func=cmd_converge)

    bag = sub.add_parser('bag', help='bag tools')
    bag_sub = bag.add_subparsers(dest='bag_command', required=True, parser_class=common.Parser)
    info = bag_sub.add_parser('info', help='describe a bag: topics, frames, trial metadata')
    common.add_option(info, 'path')
    info.set_defaults(func=cmd_bag_info)
    rewrite = bag_sub.add_parser(
        'rewrite',
        help=(
            "copy a bag into the current writer's layout (rosbag2 Jazzy, "
            'metadata version 9, type hashes); messages and trial unchanged'
        ),
    )
    common.add_options(rewrite, REWRITE_FLAGS)
    rewrite.set_defaults(func=cmd_bag_rewrite)


def cmd_import(args: argparse.Namespace) -> int:
    """Import the published dataset's per-frame clouds into one bag per trial."""
    from cloth_bench_ros.core.cleaning import scene_cleaning  # lazy: scipy's k-d tree, +0.3 s
    from cloth_bench_ros.data.importer import import_dataset  # lazy: the cleaning, +0.3 s

    if not args.output:  # not argparse's required: the old --out gives it too
        raise common.UserError('import: --output DIR is required (the directory for the bags)')
    transform = common.read_transform(args.transform) if args.transform else None
    bags = import_dataset(
        Path(args.root),
        Path(args.output),
        transform=transform,
        progress=not args.no_progress,
        overwrite=args.overwrite,
        cleaning=scene_cleaning(voxel=args.voxel) if args.clean else None,
    )
    for bag in bags:
        print(bag)
    print(f'imported {len(bags)} trial(s) into {args.output}')
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    """Write a synthetic reference bag."""
    from cloth_bench_ros.data.synth import synth_command  # lazy: the cleaning, +0.2 s

    suffix = '' if args.reference == 'mujoco' else '_' + args.reference.replace('-', '_')
    out = Path(args.output) if args.output else Path(f'{args.cloth}_{args.primitive}{suffix}')
    bag = synth_command(
        args.cloth,
        args.primitive,
        out,
        seed=args.seed,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        reference=args.reference,
        rate_hz=args.rate,
        device=args.device,
    )
    print(f'synthetic bag written: {bag}')
    return 0


def cmd_converge(args: argparse.Namespace) -> int:
    """Run a reference's convergence study on the executor; print and save its table."""
    from cloth_bench_ros.studies import (  # lazy: Dask, the engines, +1.0 s on --help
        dask_executor, reference_convergence as rc,
    )

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
    with dask_executor.open_client(args.scheduler, args.workers) as client:
        study.run(out, lambda *a: dask_executor.run_tasks(client, *a))
    rows = study.rows()
    rc.save(rows, study, out / 'convergence.json')
    print(rc.format_rows(rows))
    return 0 if all(not r.get('error') for r in rows) else 1


def cmd_bag_info(args: argparse.Namespace) -> int:
    """Describe a bag: topics, frames, trial metadata."""
    from cloth_bench_ros.data import describe  # lazy: the bag readers, +0.2 s on --help

    print(describe(Path(args.path)))
    return 0


def cmd_bag_rewrite(args: argparse.Namespace) -> int:
    """Copy a bag into the current writer's layout, checking the messages are unchanged."""
    from cloth_bench_ros.data import bag_reader, bag_rewrite  # lazy: the bag readers, +0.3 s

    counts = bag_rewrite.rewrite_bag(Path(args.src), Path(args.dst), args.change_of_phase_frame)
    changed = ''
    if args.change_of_phase_frame is not None:
        with bag_reader.BagReader(Path(args.dst)) as rewritten:
            trial = rewritten.trial
        frame = trial.change_of_phase_frame if trial is not None else None
        changed = f'; change of phase set to frame {frame}'
    print(
        f'rewrote {args.src} -> {args.dst}: {sum(counts.values())} messages, unchanged'
        f' (checked){changed}'
    )
    return 0
