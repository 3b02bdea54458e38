"""`sweep`, `report`, `stress` and `cross-reference` as they run (parsers: cli/studies.py)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.cli import bag_inputs, common
from cloth_bench_ros.cli.studies import TOLERANCE_ABS, TOLERANCE_REL
from cloth_bench_ros.engines.presets import fitted_device, fitted_elsewhere
from cloth_bench_ros.identify.spec import OBJECTIVES
from cloth_bench_ros.metric_choice import DEFAULT_METRIC
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.rank.cross_reference import identified_rankings
from cloth_bench_ros.report.cross_reference import cross_reference_markdown
from cloth_bench_ros.report.document import report_directory
from cloth_bench_ros.safe_io import atomic_write_text, check_output_dir
from cloth_bench_ros.studies import stress, stress_cases
from cloth_bench_ros.studies.cross_reference import cross_reference_cells, DEFAULT_ENTRANTS
from cloth_bench_ros.studies.errors import StudyInterrupted
from cloth_bench_ros.sweep import study as sw


def say_fitted_elsewhere(cells: list, presets: Path | None) -> None:
    """Print, per engine and device, one line where the cells' presets were fitted elsewhere."""
    fitted: dict[tuple[str, str], set] = {}
    for cell in cells:
        fitted.setdefault((cell.engine, cell.device), set()).add(
            fitted_device(cell.engine, cell.cloth, cell.primitive, presets, cell.model or None))
    for (engine, device), devices in sorted(fitted.items()):
        note = fitted_elsewhere(engine, device, devices)
        if note:
            print(note)


def scores_every_metric(args: argparse.Namespace) -> bool:
    """Return whether a study's cells need every metric: asked for, or --metric is not CD/HD."""
    return bool(getattr(args, 'all_metrics', False)) or args.metric not in OBJECTIVES


def cmd_sweep(args: argparse.Namespace) -> int:
    """Run a sweep's cells on the executor, resuming what is done."""
    settings = args.mode == 'settings'
    engines = validation.unique(
        args.engine or [e for e in sw.DEFAULT_ENGINES if e in common.available_engines()],
        '--engine',
    )
    plan = sw.SweepPlan(
        args.mode,
        engines,
        args.rate or [],
        args.cloth or [],
        args.primitive or [],
        args.seeds,
        args.seed_start,
        Path(args.bag_dir) if args.bag_dir else None,
        args.grid,
        common.engine_overrides(args.set, engines),
        args.pacing,
        args.step_per_target,
        args.keep_frames,
        args.axis or [],
        common.preset_set(args),
        all_metrics=scores_every_metric(args),
        settle=args.settle,
    )
    cells = sw.with_inputs(plan.cells(), args.task, args.cloth_mesh)  # read and checked once
    if plan.left_out:
        print(
            f'cloth-bench sweep: --presets {plan.presets.name if plan.presets else ""} has no'
            f' values for {", ".join(plan.left_out)}: left out (--cloth and --primitive insist)'
        )
    out = (
        Path(args.output)
        if args.output
        else Path('results') / ('settings' if settings else 'sweep')
    )
    cells = sw.with_kept_scoring(cells, sw.load_rows(out / sw.RESULTS_FILE))
    if args.dry_run:
        print(sw.estimate(cells, out, args.workers))
        return 0
    where = (
        f'scheduler {args.scheduler}'
        if args.scheduler
        else f'{args.workers or sw.default_workers()} local workers'
    )
    print(
        f'cloth-bench sweep ({args.mode}): {len(engines)} engines x'
        f' {len({c.rate_hz for c in cells})} rates x {len({c.cloth for c in cells})} cloths x'
        f' {len({c.primitive for c in cells})} tasks x {len(plan.seeds())} seeds'
        + (f' x {len({c.config for c in cells})} configurations' if settings else '')
        + f' = {len(cells)} cells -> {out / sw.RESULTS_FILE} on {where}',
        flush=True,
    )
    say_fitted_elsewhere(cells, plan.presets.directory if plan.presets else None)
    try:
        outcome = sw.run_sweep(
            cells,
            out,
            args.workers,
            progress=not args.no_progress,
            retry_errors=args.retry_errors,
            scheduler=args.scheduler,
        )
    except KeyboardInterrupt:
        kept = len(
            {c.key() for c in cells} & {sw.row_key(r) for r in sw.load_rows(out / sw.RESULTS_FILE)}
        )
        raise StudyInterrupted(
            f'sweep interrupted: {kept} of {len(cells)} cells are in {out / sw.RESULTS_FILE}; '
            'run the same command again to resume'
        ) from None
    print(
        f'sweep: {outcome.ran} cells run in {outcome.wall_s:.1f} s ({outcome.skipped} already'
        f' done), {outcome.diverged} diverged, {outcome.errors} errors; results: {outcome.results}'
    )
    if args.report:
        return render(
            out, out / 'report', None, OPTIONS['rate_hz'].default, OPTIONS['cloth'].default,
            TOLERANCE_REL, TOLERANCE_ABS, args.metric,
        )
    return 0


def render(
    results: Path,
    out: Path,
    stress: Path | None,
    rate: float,
    cloth: str,
    tol_rel: float,
    tol_abs: float,
    metric: str = DEFAULT_METRIC,
) -> int:
    """Render the report of `results` into `out` and print its headline tables."""
    outcome = report_directory(
        Path(results), out, stress, rate, cloth, tol_rel, tol_abs, metric=metric
    )
    for name in ('table3', 'rank'):
        if name in outcome.tables:
            print(outcome.tables[name].markdown())
    for note in outcome.recommendations:
        print(
            f'recommended {note["engine"]} {note["cloth"]} {note["primitive"]} {note["rate_hz"]:g}'
            f' Hz: {note["recommended"]} (CD {note["recommended_cd"]:.4f} m,'
            f' {note["recommended_step_ms"]:.3f} ms/step); most accurate {note["best"]} (CD'
            f' {note["best_cd"]:.4f} m, {note["best_step_ms"]:.3f} ms/step)'
        )
    print(
        f'report: {outcome.markdown} and {outcome.html}, {len(outcome.images)} plots, '
        f'{len(outcome.tables)} tables (CSV) in {out}'
    )
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Render the report of a results file or directory."""
    results = Path(args.results)
    base = results if results.is_dir() else results.parent
    out = Path(args.output) if args.output else base / 'report'
    return render(
        results,
        out,
        Path(args.stress) if args.stress else None,
        args.rate,
        args.fig5_cloth,
        args.tolerance_rel,
        args.tolerance_abs,
        args.metric,
    )


def cmd_stress(args: argparse.Namespace) -> int:
    """Run the stress suite and print which cases diverged."""
    available = common.available_engines()
    engines = validation.unique(
        args.engine or [e for e in ('mujoco', 'bullet', 'newton') if e in available], '--engine'
    )
    presets = common.preset_set(args)
    cases = stress_cases.select_cases(
        engines, args.case, args.max_wall_s, presets, args.task or '', args.cloth_mesh or ''
    )
    if args.cloth_mesh and any(c.grid for c in stress_cases.select_cases(engines, args.case)):
        print(f'stress: the cases of their own grid are left out: --cloth-mesh {args.cloth_mesh} '
              'is the cloth of every case')
    if args.device is not None:  # Newton's cases on the device asked for
        if 'newton' not in engines:
            raise common.UserError('--device applies to engine newton, not part of this run')
        cases = [
            replace(c, params={**c.params, 'device': args.device}) if c.engine == 'newton' else c
            for c in cases
        ]
    if args.list:
        for c in cases:
            print(f'{c.engine:<8} {c.name:<24} {c.description}')
        return 0
    default_out = 'stress' if presets.is_default else f'stress_{Path(presets.name).name}'
    out = Path(args.output) if args.output else Path('results') / default_out
    rows = stress.run_suite(
        cases, out, args.workers, progress=not args.no_progress, scheduler=args.scheduler
    )
    print(stress.stress_table(rows).markdown())
    for engine, diverged in stress.verdict(rows).items():
        n = sum(r['engine'] == engine for r in rows)
        print(
            f'{engine}: {len(diverged)} of {n} cases diverged'
            + (f' ({", ".join(diverged)})' if diverged else '')
        )
    print(f'stress: {out}/stress.jsonl, {out}/stress.md')
    return 0


def cmd_cross_reference(args: argparse.Namespace) -> int:
    """Score every engine against both synthetic references on the executor; print the table."""
    available = common.available_engines()
    entrants = [(e, o) for e, o in DEFAULT_ENTRANTS if e in available]
    if args.device is not None:  # Newton's entrants on the device asked for
        entrants = [(e, {**o, 'device': args.device} if e == 'newton' else o) for e, o in entrants]
    cells, missing = cross_reference_cells(
        args.cloth,
        args.primitive or ['dynamic', 'quasi_static'],
        range(args.seed_start, args.seed_start + args.seeds),
        args.rate,
        entrants,
        all_metrics=scores_every_metric(args),
    )
    for line in missing:
        print(f'cross-reference: {line}; that entrant runs with its preset only')
    for bag in sorted({c.bag for c in cells}):
        bag_inputs.check_bag(Path(bag))
    out = check_output_dir(args.output)
    results = out / sw.RESULTS_FILE
    cells = sw.with_kept_scoring(cells, sw.load_rows(results))
    print(f'cloth-bench cross-reference: {len(cells)} cells -> {results}', flush=True)
    try:
        outcome = sw.run_sweep(
            cells,
            out,
            args.workers,
            progress=not args.no_progress,
            desc='cross-reference',
            scheduler=args.scheduler,
        )
    except KeyboardInterrupt:
        kept = len({c.key() for c in cells} & {sw.row_key(r) for r in sw.load_rows(results)})
        raise StudyInterrupted(
            f'cross-reference interrupted: {kept} of {len(cells)} cells are in {results}; '
            'run the same command again to resume'
        ) from None
    print(
        f'cross-reference: {outcome.ran} cells run in {outcome.wall_s:.1f} s ({outcome.skipped}'
        f' already done), {outcome.diverged} diverged, {outcome.errors} errors'
    )
    keys = {c.key() for c in cells}
    rows = [r for r in sw.load_rows(results) if sw.row_key(r) in keys]
    text = cross_reference_markdown(rows, identified_rankings(rows, args.metric), args.metric)
    atomic_write_text(out / 'cross_reference.md', text + '\n')
    print(text)
    return 0
