"""`cloth-bench import`, `synth`, `converge` and `bag` as they run (parsers: cli/data.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.cli import common
from cloth_bench_ros.core.cleaning import scene_cleaning
from cloth_bench_ros.data import bag_reader, bag_rewrite, describe
from cloth_bench_ros.data.importer import import_dataset
from cloth_bench_ros.data.synth import synth_command
from cloth_bench_ros.safe_io import check_output_dir
from cloth_bench_ros.studies import dask_executor, reference_convergence as rc


def cmd_import(args: argparse.Namespace) -> int:
    """Import the published dataset's per-frame clouds into one bag per trial."""
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
    print(describe(Path(args.path)))
    return 0


def cmd_bag_rewrite(args: argparse.Namespace) -> int:
    """Copy a bag into the current writer's layout, checking the messages are unchanged."""
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
