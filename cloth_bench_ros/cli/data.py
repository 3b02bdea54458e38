"""`cloth-bench import`, `synth` and `bag`: making and inspecting the bags runs score against."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.cli import common
from cloth_bench_ros.core.cleaning import scene_cleaning
from cloth_bench_ros.options import Option
from cloth_bench_ros.safe_io import check_output_dir


def _frame_or_detected(text: str, label: str) -> int | str:
    if text == 'detected':
        return 'detected'
    frame = validation.parse_integer(text, label)
    return validation.integer(frame, label, 0, validation.MAX_FRAME)


REFERENCES = ('mujoco', 'newton-vbd')
IMPORT_FLAGS: tuple[common.Flag, ...] = (
    Option(
        'root', str, None, 'dataset root: <root>/<cloth>_rag_<trial>/<primitive>/cloud/'
        '<NNNNN>.ply|.pcd', flag='root',
    ),
    ('output', {'flag': '--out', 'required': True, 'help': 'directory for the bags'}),
    Option(
        'transform', str, None, '4x4 matrix into the simulation frame (text file of 16 numbers, or'
        ' .npy)', flag='--transform',
    ),
    ('overwrite', {'help': 'replace bags that exist'}),
    Option(
        'clean', bool, False, 'crop to the workspace, remove the table plane and outliers '
        '(core.cleaning) before writing', flag='--clean', action='store_true',
    ),
    ('voxel', {'help': 'with --clean: voxel size (0: off)'}),
    'quiet',
)
SYNTH_FLAGS: tuple[common.Flag, ...] = (
    ('output', {'flag': '--out', 'help': 'bag directory (default <cloth>_<primitive>)'}),
    ('seed', {'help': 'sensor noise and reference seed'}),
    Option(
        'reference', str, 'mujoco', 'reference model: mujoco (config/synth.yaml, default) or '
        'newton-vbd (config/synth_newton_vbd.yaml); default bag name '
        '<cloth>_<primitive>[_newton_vbd]', flag='--reference', choices=REFERENCES,
    ),
    Option(
        'rate', float, None, "the reference's step rate, a multiple of 30 (default: the "
        "reference file's)", flag='--rate', low=0.0, low_open=True, unit='Hz', metavar='HZ',
    ),
    ('overwrite', {'help': 'replace the bag if it exists'}),
    'quiet',
)
CONVERGE_FLAGS: tuple[common.Flag, ...] = (
    Option('reference', str, 'mujoco', 'the reference model', flag='--reference',
           choices=REFERENCES),
    Option(
        'axis', str, None, 'setting to refine (repeatable; default all three)', flag='--axis',
        action='append', choices=('iterations', 'rate', 'grid'),
    ),
    Option(
        'levels', int, 1, 'refinements per axis: iterations and rate x2 each, grid spacing /1.5',
        flag='--levels', low=1,
    ),
    Option(
        'duration', float, None, 'seconds of the quintic part (default: the whole trial)',
        flag='--duration', low=0.0, low_open=True, unit='s', metavar='S',
    ),
    Option(
        'score', str, None, "score this engine's preset (tested grid) against every run "
        '(repeatable)', flag='--score', action='append', metavar='ENGINE',
    ),
    ('output', {'help': 'directory: one .npz per run (reused) and convergence.json (default '
                'results/convergence/<reference>_<cloth>_<primitive>)'}),
)
REWRITE_FLAGS: tuple[common.Flag, ...] = (
    Option('src', str, None, 'bag to read', flag='src'),
    Option('dst', str, None, 'new bag directory (must not exist or be empty)', flag='dst'),
    Option(
        'change_of_phase_frame', int, None, 'store this change-of-phase frame in the trial '
        '(dynamic task), or the first table contact found in the clouds',
        flag='--change-of-phase-frame', metavar='N|detected', validate=_frame_or_detected,
    ),
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register import, synth, converge and bag (info, rewrite)."""
    imp = sub.add_parser(
        'import', help='turn the published dataset (PLY/PCD per frame) into one bag per trial'
    )
    common.add_options(imp, IMPORT_FLAGS)
    imp.set_defaults(func=cmd_import)

    synth = sub.add_parser(
        'synth',
        parents=[common.scene_options()],
        help='make a synthetic reference bag (reference simulation seen by a virtual Kinect)',
    )
    common.add_options(synth, SYNTH_FLAGS)
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
    common.add_option(info, Option('path', str, None, 'the bag', flag='path'))
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
    from cloth_bench_ros.data.importer import import_dataset  # lazy: +0.2 s on --help

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
    from cloth_bench_ros.data.synth import synth_command  # lazy: +0.2 s on --help

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
