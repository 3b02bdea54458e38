"""`cloth-bench hil` as it runs: its runs, or the recommendation exported (parser: cli/hil.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

from cloth_bench_ros.cli import bag_inputs, common, hil_rate
from cloth_bench_ros.cli.common import UserError
from cloth_bench_ros.core.deadline import deadline_rule
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.hil import study as hil
from cloth_bench_ros.hil.layout import resolve_layout
from cloth_bench_ros.hil.recommendation import all_recommendations, provenance, recommendation_yaml
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.paths import bundled_bag
from cloth_bench_ros.report.hil import hil_table, text_table, write_hil_report
from cloth_bench_ros.safe_io import atomic_write_text
from cloth_bench_ros.studies.cells import config_label, set_label, set_values
from cloth_bench_ros.studies.cloth import study_inputs
from cloth_bench_ros.studies.results import load_rows


def cmd_hil(args: argparse.Namespace) -> int:
    """Run each engine and rate with targets on the wall clock and print the deadline table."""
    if args.budget is None:
        args.budget = hil.HIL_DEADLINE_BUDGET
    if args.export_recommended:
        return _export_recommended(args)
    engines = args.engine or ['mujoco']
    for name in engines:
        engine_class(name)
    if args.config == 'recommended' and args.grid:
        raise UserError('--grid and --config recommended both choose the mesh: give one')
    if args.grid and len(args.grid) > 1 and not args.find_rate:
        raise UserError('several --grid need --find-rate (one real-time run has one mesh)')
    if args.find_rate and args.config == 'recommended':
        raise UserError(
            '--find-rate searches the rate of one configuration; --config recommended changes'
            ' with the rate: give --grid/--set instead'
        )
    grids = [tuple(g) for g in args.grid] if args.grid else [None]
    if args.cloth_mesh and args.config == 'recommended':
        raise UserError('--cloth-mesh and --config recommended: the recommendation is a grid; '
                        'give one')
    for grid in grids:  # a bad task file or mesh (or a mesh with --grid): one line, first
        study_inputs(args.primitive, args.task or '', args.cloth_mesh or '', grid, None,
                     OPTIONS['rate_hz'].default)
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    bag_inputs.check_bag(bag)
    overrides = common.engine_overrides(args.set, engines)
    out = Path(args.output) if args.output else Path('results') / 'hil'
    settings = Path(args.settings) if args.settings else hil.DEFAULT_SETTINGS
    processes = (
        'one process'
        if args.in_process
        else '3 processes over DDS (controller, simulator, recorder+evaluator)'
    )
    print(
        f'cloth-bench hil: {args.cloth} {args.primitive}, targets on the wall clock, {processes};'
        f' bag {bag}'
    )
    try:
        layout = resolve_layout(args.layout, args.cpu, args.fifo, args.busy_wait)
    except common.ClothBenchError as exc:
        raise UserError(str(exc)) from None
    print(layout.line())
    print(
        f'{deadline_rule(args.budget)}; a run holds its rate with under'
        f' {100 * args.miss_threshold:g} % of the deadlines missed'
    )
    presets = common.preset_set(args)
    results = []
    remedies = []
    bases = []
    for engine, grid in ((e, g) for e in engines for g in grids):
        default = args.rate_min if args.find_rate else OPTIONS['rate_hz'].default
        for rate in args.rate or [default]:
            user = dict(overrides.get(engine, {}))  # --set, on top of everything
            base = set_values(presets, engine, args.cloth, args.primitive, user.get('model'))
            params = {**base, **user}
            label = set_label(presets, config_label(grid, user))
            config = hil.HilConfig(
                engine,
                float(rate),
                bag,
                args.cloth,
                args.primitive,
                args.seed,
                grid,
                tuple(sorted(params.items())),
                label,
                not args.in_process,
                layout.cpu,
                layout.fifo,
                not args.no_freeze_gc,
                layout.busy_wait,
                args.duration,
                live=tuple(sorted(common.live_parameters(args).items())),
                task_file=args.task or '',
                cloth_mesh=args.cloth_mesh or '',
            )
            if args.config == 'recommended':
                rec, source = hil.recommended(
                    engine,
                    args.cloth,
                    args.primitive,
                    float(rate),
                    settings,
                    args.tolerance_rel,
                    args.tolerance_abs,
                    args.budget,
                )
                label = set_label(
                    presets, rec.config + (f',{config_label(None, user)}' if user else '')
                )
                config = hil.with_config(config, label, rec.grid, {**base, **rec.params, **user})
                print(
                    f'{engine} at {rate:g} Hz: recommended `{rec.config}` from {source}: CD'
                    f' {rec.cd:.4f} m (best {rec.best_config}: {rec.best_cd:.4f} m), step p99'
                    f' {rec.step_p99_ms:.3f} ms '
                    + ('under' if rec.meets_deadline else 'NOT under')
                    + f' {1e3 * args.budget / rate:g} ms'
                )
            if args.find_rate:
                bases.append(config)
                continue
            print(
                f'running {engine} at {rate:g} Hz, configuration {config.config} ...', flush=True
            )
            check, timing = hil_rate.warmup_check(config, args.budget)
            result = hil.run_hil(config, out, lockstep=not args.no_lockstep)
            results.append(result)
            print('  simulator process: ' + '; '.join(result.realtime))
            remedies.append((config, result, check, timing))
    if args.find_rate:
        return hil_rate.find_rates(args, bases, out)
    rows = [r.row() for r in results]
    hil.write_results(results, out)
    print(text_table(hil_table(rows)))
    print(
        "latency: target due on the controller's wall-clock schedule -> state back at the"
        ' controller; miss: latency > 1 / rate; skipped: targets the simulator never stepped (a'
        ' newer one was waiting); RTF: simulated / wall time; CPU busy: all cores, any process,'
        ' during the run'
    )
    report = write_hil_report(rows, out, out / 'report')
    print(
        f'results: {out / "hil.jsonl"}; report: {report} (latency over time and histogram per run)'
    )
    for config, result, check, timing in remedies:
        line = hil_rate.remedy_line(
            config, result, check, timing, args, args.config == 'recommended'
        )
        if line:
            print(line)
    return 1 if any(r.problems for r in results) else 0


def _export_recommended(args: argparse.Namespace) -> int:
    """Export the settings sweep's recommendation per engine, task and rate."""
    if not args.settings:
        raise UserError(
            "--export-recommended needs --settings RESULTS (a settings sweep's results)"
        )
    rows = load_rows(Path(args.settings))
    recs = all_recommendations(rows, args.tolerance_rel, args.tolerance_abs, args.budget)
    if not recs:
        raise UserError(
            f'settings {args.settings}: no settings-sweep rows with a stable configuration'
        )
    atomic_write_text(
        Path(args.export_recommended),
        recommendation_yaml(
            recs,
            provenance(rows, args.tolerance_rel, args.tolerance_abs, args.budget, args.note or ''),
        ),
    )
    for r in recs:
        print(
            f'{r.engine} {r.cloth} {r.primitive} {r.rate_hz:g} Hz: {r.config} (CD {r.cd:.4f} m,'
            f' step p99 {r.step_p99_ms:.3f} ms, deadline'
            f' {"met" if r.meets_deadline else "not met"})'
        )
    print(f'written: {args.export_recommended}')
    return 0
