"""`cloth-bench`: the command-line front door (run, trajectory, engines, bag)."""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
import warnings
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.core.trajectory import PRIMITIVES
from cloth_bench_ros.errors import ClothBenchError


class UserError(ClothBenchError):
    """Bad input from the user: printed as one line, exit status 2."""


def _option(check, name: str):
    """An argparse type from a validation check: its one-line error becomes argparse's."""
    def parse(text: str):
        try:
            return check(text, name)
        except validation.InputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    parse.__name__ = name  # argparse names the type in some messages
    return parse


def _rate(text: str) -> float:
    return _option(lambda t, n: validation.rate_hz(validation.parse_number(t, n), n), "rate")(text)


def _seed(text: str) -> int:
    return _option(lambda t, n: validation.seed(validation.parse_integer(t, n), n), "seed")(text)


def _number(check, name: str):
    """An argparse type for a number checked by `check(value, name)` (validation.positive, ...)."""
    return _option(lambda t, n: check(validation.parse_number(t, n), n), name)


def _frame(text: str) -> int | None:
    return _option(lambda t, n: validation.frame_index(validation.parse_integer(t, n), n), "change-of-phase-frame")(text)


def check_bag(bag: Path, topic: str | None = None) -> None:
    """Fail early, with one line naming the bag, unless the chosen cloud topic's first frame decodes."""
    from cloth_bench_ros.data import BagReader
    from cloth_bench_ros.data.messages import deserialize
    from cloth_bench_ros.core.pointcloud2 import read_xyz

    reader = BagReader(bag)
    topic = reader.cloud_topic(topic)
    first = next(reader.raw_messages([topic]), None)
    if first is None:
        raise UserError(f"bag {bag}: no PointCloud2 message on {topic} could be read")
    try:
        msg = deserialize(first[3], first[1])
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types on bad CDR
        what = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise UserError(f"bag {bag}: frame 0 on {topic} (stamp {first[2] / 1e9:.3f} s) "
                        f"is not a valid PointCloud2 ({what})") from None
    try:
        read_xyz(msg)
    except ValueError as exc:
        raise UserError(f"bag {bag}: frame 0 on {topic} (stamp {first[2] / 1e9:.3f} s): {exc}") from None


def _replay_params(args: argparse.Namespace) -> dict:
    """Recorder parameters for bags that do not say everything (plain `ros2 bag record` output)."""
    params = {"topic": args.topic or "", "start_time": args.start_time or "", "targets_topic": args.targets_topic or "",
              "clean": args.clean, "voxel": float(args.voxel), "table_plane": args.table_plane, "align_window": float(args.align_window),
              "align_step": float(args.align_step)}
    if args.transform:
        params["transform"] = [float(v) for v in _read_transform(args.transform).ravel()]
    return params


def _print_real(summary: dict) -> None:
    from cloth_bench_ros.core.evaluation import accounting_line

    real = summary["real"]
    acc = real["accounting"]
    print(accounting_line(acc))
    start = real.get("alignment") or {}
    if start:
        print(f"start of the motion: bag time {start['bag_ns'] / 1e9:.3f} s, {start['method']}, "
              f"precision +/- {start['precision_s'] * 1e3:.1f} ms")
    print(f"real points: {real['nan_points_dropped']} NaN points dropped, "
          f"{real['irregular_intervals']} intervals not at 30 Hz" + (
              f", frames from {real['frames_from']}" if real.get("frames_from") else ""))
    if acc["scored"] == 0:
        raise UserError(f"bag: no frame was scored ({accounting_line(acc)[len('real frames: '):]}); "
                        "check --start-time/--topic/--primitive")


def cmd_run(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines import engine_class
    from cloth_bench_ros.engines.presets import CLOTHS, load_preset
    from cloth_bench_ros.paths import bundled_bag
    from cloth_bench_ros.studies.pipeline import RunConfig, run_pipeline
    from cloth_bench_ros.report.run_report import result_table

    from cloth_bench_ros.safe_io import check_output_dir

    engines = validation.unique(args.engine or ["mujoco"], "--engine")
    for name in engines:
        engine_class(name)
    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    presets = Path(args.presets) if args.presets else None
    for name in engines:  # a missing directory, malformed preset file or bad value fails here, in one line
        load_preset(name, args.cloth, args.primitive, presets)
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    check_bag(bag, args.topic)
    overrides = _overrides(getattr(args, "set", None), engines)
    replay = _replay_params(args)
    out = Path(args.output) if args.output else Path("results") / f"{args.cloth}_{args.primitive}_{int(args.rate)}hz_seed{args.seed}"
    try:  # an unwritable or occupied --output is found before the run, not after it
        check_output_dir(out)
    except ValueError as exc:
        raise UserError(f"--output {exc}") from None
    config = RunConfig(bag=bag, engines=engines, rate_hz=args.rate, cloth=args.cloth, primitive=args.primitive,
                       seed=args.seed, pacing=args.pacing, output_dir=out,
                       engine_params=overrides, grid=getattr(args, "grid", None), presets_dir=presets,
                       replay=replay, change_of_phase_frame=args.change_of_phase_frame,
                       record_comparison=Path(args.record_comparison) if args.record_comparison else None,
                       comparison_figures=args.figures)
    if config.record_comparison is not None:  # checked before the run, not after it
        if config.record_comparison.exists() and any(config.record_comparison.iterdir()):
            raise UserError(f"comparison bag {config.record_comparison} already exists (not empty)")
        try:
            check_output_dir(config.record_comparison)
        except ValueError as exc:
            raise UserError(f"--record-comparison {exc}") from None
    if getattr(args, "processes", False):
        from cloth_bench_ros.studies.processes import ProcessRunError, run_processes

        try:
            summary = run_processes(config)
        except ProcessRunError as exc:
            raise UserError(f"run --processes: {exc}") from None
    else:
        summary = run_pipeline(config)
    print(f"cloth-bench run: {args.cloth} {args.primitive} at {args.rate:g} Hz, seed {args.seed}, bag {bag}")
    print(result_table(summary))
    _print_real(summary)
    print(f"report: {out}/summary.json, {out}/frames.csv")
    for key in ("bag", "figure", "animation"):
        if key in summary.get("comparison", {}):
            print(f"comparison {key}: {summary['comparison'][key]}")
    return 0


def cmd_trajectory(args: argparse.Namespace) -> int:
    from cloth_bench_ros.core.trajectory import sample_quintic, to_csv

    sys.stdout.write(to_csv(sample_quintic(args.primitive, args.rate)))
    return 0


def cmd_engines(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines import engine_class, known_engines

    print(f"{'engine':<10} {'available':<10} {'version':<10} reason")
    for info in known_engines():
        print(f"{info.name:<10} {'yes' if info.available else 'no':<10} {info.version or '-':<10} {info.reason}")
    if getattr(args, "warm", False):
        for info in known_engines():
            if info.available:
                start = time.perf_counter()
                engine_class(info.name).warm()
                print(f"warmed {info.name} in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_cross_reference(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines.presets import CLOTHS
    from cloth_bench_ros.report import cross_reference as xr
    from cloth_bench_ros.safe_io import atomic_write_text, check_output_dir
    from cloth_bench_ros.studies import sweep as sw

    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    if args.seeds < 1:
        raise UserError(f"--seeds must be at least 1, got {args.seeds}")
    if not args.rate > 0:
        raise UserError(f"--rate must be a positive number of Hz, got {args.rate:g}")
    available = _available_engines()
    entrants = [(e, o) for e, o in xr.DEFAULT_ENTRANTS if e in available]
    cells = xr.cross_reference_cells(args.cloth, args.primitive or ["dynamic", "quasi_static"],
                                     range(args.seeds), args.rate, entrants)
    for bag in sorted({c.bag for c in cells}):
        check_bag(Path(bag))
    out = check_output_dir(args.output)
    results = out / sw.RESULTS_FILE
    done = {sw.row_key(r) for r in sw.load_rows(results)}
    todo = [c for c in cells if c.key() not in done]
    print(f"cloth-bench cross-reference: {len(cells)} runs, {len(cells) - len(todo)} already in {results}")
    xr.run_cross_reference(todo, out, on_row=lambda row: sw.append_row(results, row))
    table = xr.cross_reference_table(sw.load_rows(results))
    text = table.markdown() if table is not None else "(no rows)"
    atomic_write_text(out / "cross_reference.md", text + "\n")
    print(text)
    return 0


def cmd_bag_info(args: argparse.Namespace) -> int:
    from cloth_bench_ros.data import describe

    print(describe(Path(args.path)))
    return 0


def cmd_bag_rewrite(args: argparse.Namespace) -> int:
    from cloth_bench_ros.data.bag_rewrite import rewrite_bag

    counts = rewrite_bag(Path(args.src), Path(args.dst))
    print(f"rewrote {args.src} -> {args.dst}: {sum(counts.values())} messages, unchanged (checked)")
    return 0


def _grid(text: str) -> tuple[int, int]:
    return _option(validation.parse_grid, "grid")(text)


def _scheduler(text: str) -> str:
    from cloth_bench_ros.studies.executor import check_scheduler_address

    try:
        return check_scheduler_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _overrides(specs: list[str] | None, engines: list[str] | None = None) -> dict[str, dict]:
    """--set engine.param=value (repeatable) -> {engine: {param: value}}, checked against the schemas."""
    from cloth_bench_ros.engines import engine_class

    overrides = validation.parse_overrides(specs)
    for engine, params in overrides.items():
        if engines is not None and engine not in engines:
            raise UserError(f"--set {engine}.…: engine {engine} is not part of this run ({', '.join(engines)})")
        try:
            engine_class(engine).validate_params(params)
        except ValueError as exc:
            raise UserError(f"--set {engine}: {exc}") from None
    return overrides


def _available_engines() -> list[str]:
    from cloth_bench_ros.engines import known_engines

    return [i.name for i in known_engines() if i.available]


def cmd_sweep(args: argparse.Namespace) -> int:
    from cloth_bench_ros.studies import sweep as sw

    settings = args.mode == "settings"
    engines = validation.unique(args.engine or [e for e in sw.DEFAULT_ENGINES if e in _available_engines()], "--engine")
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    plan = sw.SweepPlan(args.mode, engines, args.rate or [], args.cloth or [], args.primitive or list(sw.DEFAULT_PRIMITIVES),
                        args.seeds, args.seed_start, Path(args.bag_dir) if args.bag_dir else None, args.grid,
                        _overrides(args.set, engines), args.pacing, args.step_per_target, args.keep_frames,
                        args.axis or [])
    cells = plan.cells()
    out = Path(args.output) if args.output else Path("results") / ("settings" if settings else "sweep")
    if args.dry_run:
        print(sw.estimate(cells, out, args.workers))
        return 0
    where = f"scheduler {args.scheduler}" if args.scheduler else f"{args.workers or sw.default_workers()} local workers"
    print(f"cloth-bench sweep ({args.mode}): {len(engines)} engines x {len(set(c.rate_hz for c in cells))} rates x "
          f"{len({c.cloth for c in cells})} cloths x {len({c.primitive for c in cells})} tasks x "
          f"{len(plan.seeds())} seeds" + (f" x {len({c.config for c in cells})} configurations" if settings else "")
          + f" = {len(cells)} cells -> {out / sw.RESULTS_FILE} on {where}", flush=True)
    outcome = sw.run_sweep(cells, out, args.workers, progress=not args.no_progress, retry_errors=args.retry_errors,
                           scheduler=args.scheduler)
    print(f"sweep: {outcome.ran} cells run in {outcome.wall_s:.1f} s ({outcome.skipped} already done), "
          f"{outcome.diverged} diverged, {outcome.errors} errors; results: {outcome.results}")
    if args.report:
        return _render(out, out / "report", None, 100.0, "towel", 0.05, 0.002)
    return 0


def _render(results: Path, out: Path, stress: Path | None, rate: float, cloth: str, tol_rel: float,
            tol_abs: float) -> int:
    from cloth_bench_ros.report.document import report_directory

    outcome = report_directory(Path(results), out, stress, rate, cloth, tol_rel, tol_abs)
    if "table2" in outcome.tables:
        print(outcome.tables["table2"].markdown())
    for note in outcome.recommendations:
        print(f"recommended {note['engine']} {note['cloth']} {note['primitive']} {note['rate_hz']:g} Hz: "
              f"{note['recommended']} (CD {note['recommended_cd']:.4f} m, {note['recommended_step_ms']:.3f} ms/step); "
              f"most accurate {note['best']} (CD {note['best_cd']:.4f} m, {note['best_step_ms']:.3f} ms/step)")
    print(f"report: {outcome.markdown} and {outcome.html}, {len(outcome.images)} plots, "
          f"{len(outcome.tables)} tables (CSV) in {out}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    results = Path(args.results)
    base = results if results.is_dir() else results.parent
    out = Path(args.output) if args.output else base / "report"
    if not (args.tolerance_rel >= 0 and args.tolerance_abs >= 0):
        raise UserError("--tolerance-rel and --tolerance-abs must be >= 0")
    return _render(results, out, Path(args.stress) if args.stress else None, args.rate, args.fig5_cloth,
                   args.tolerance_rel, args.tolerance_abs)


def cmd_stress(args: argparse.Namespace) -> int:
    from cloth_bench_ros.studies.stress import run_suite, select_cases, stress_table, verdict

    engines = validation.unique(args.engine or [e for e in ("mujoco", "bullet", "newton") if e in _available_engines()],
                                "--engine")
    cases = select_cases(engines, args.case, args.max_wall_s)
    if args.list:
        for c in cases:
            print(f"{c.engine:<8} {c.name:<24} {c.description}")
        return 0
    out = Path(args.output) if args.output else Path("results") / "stress"
    rows = run_suite(cases, out, args.workers, progress=not args.no_progress, scheduler=args.scheduler)
    print(stress_table(rows).markdown())
    for engine, diverged in verdict(rows).items():
        n = sum(r["engine"] == engine for r in rows)
        print(f"{engine}: {len(diverged)} of {n} cases diverged" + (f" ({', '.join(diverged)})" if diverged else ""))
    print(f"stress: {out}/stress.jsonl, {out}/stress.md")
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines.presets import CLOTHS
    from cloth_bench_ros.paths import bundled_bag
    from cloth_bench_ros.studies.identify import IdentifySpec, identify

    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    for name, value, least in (("--trials", args.trials, 1), ("--validate-seeds", args.validate_seeds, 0),
                               ("--seed", args.seed, 0), ("--max-frames", args.max_frames or 1, 1),
                               ("--batch", args.batch or 1, 1), ("--workers", args.workers or 1, 1)):
        if value < least:
            raise UserError(f"{name} must be at least {least}, got {value}")
    if not (args.span > 1 and args.span < float("inf")):
        raise UserError(f"--span must be a finite factor > 1, got {args.span}")
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    check_bag(bag)
    fixed = _overrides(args.set, [args.engine]).get(args.engine, {})
    out = Path(args.output) if args.output else Path("results") / "identify" / f"{args.engine}_{args.cloth}_{args.primitive}"
    spec = IdentifySpec(args.engine, args.cloth, args.primitive, bag, out, args.sampler, args.trials, args.objective,
                        [p.strip() for p in args.params.split(",") if p.strip()] if args.params else [], args.seed,
                        args.rate, args.grid, fixed, args.span, args.max_frames, args.batch, args.validate_seeds,
                        Path(args.bag_dir) if args.bag_dir else None)
    print(f"cloth-bench identify: {args.engine}, {args.cloth} {args.primitive}, {args.objective.upper()}, "
          f"sampler {args.sampler}, {args.trials} trials each; bag {bag}; output {out}", flush=True)
    outcome = identify(spec, args.scheduler, args.workers, progress=not args.no_progress)
    s = outcome.summary
    for name, result in s["per_sampler"].items():
        print(f"{name:<6} best {args.objective.upper()} {result['value']:.5f} m after {result['trials']} trials")
    print(f"identified ({s['best_sampler']}): " + ", ".join(f"{k}={v:.6g}" for k, v in s["params"].items()))
    print(f"{args.objective.upper()} on seed {args.seed}: preset {s['preset_value']:.5f} m -> identified "
          f"{s['value']:.5f} m")
    for v in s["validation"]:
        print(f"held-out seeds, {Path(v['bag']).name}: preset {v['preset']['mean']:.5f} ± {v['preset']['std']:.5f} m, "
              f"identified {v['identified']['mean']:.5f} ± {v['identified']['std']:.5f} m "
              f"({v['identified']['ok']} of {v['identified']['n']} runs ok)")
    print(f"preset: {outcome.preset_file} (use: cloth-bench run --presets {out}); "
          f"{outcome.wall_s:.0f} s; report: cloth-bench report {out}")
    return 0


def cmd_hil(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines import engine_class
    from cloth_bench_ros.engines.presets import CLOTHS
    from cloth_bench_ros.paths import bundled_bag
    from cloth_bench_ros.report.hil import hil_table, text_table, write_hil_report
    from cloth_bench_ros.studies import hil
    from cloth_bench_ros.studies.sweep import config_label

    if args.budget is None:
        args.budget = hil.HIL_DEADLINE_BUDGET
    if args.export_recommended:
        return _export_recommended(args)
    engines = args.engine or ["mujoco"]
    for name in engines:
        engine_class(name)
    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    if args.config == "recommended" and args.grid:
        raise UserError("--grid and --config recommended both choose the mesh: give one")
    if args.duration < 0 or args.budget <= 0:
        raise UserError("--duration must be >= 0 and --deadline-budget > 0")
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    check_bag(bag)
    overrides = _overrides(args.set, engines)
    out = Path(args.output) if args.output else Path("results") / "hil"
    settings = Path(args.settings) if args.settings else hil.DEFAULT_SETTINGS
    layout = "one process" if args.in_process else "3 processes over DDS (controller, simulator, recorder+evaluator)"
    print(f"cloth-bench hil: {args.cloth} {args.primitive}, targets on the wall clock, {layout}; bag {bag}")
    results = []
    for engine in engines:
        for rate in args.rate or [100.0]:
            params = dict(overrides.get(engine, {}))
            config = hil.HilConfig(engine, float(rate), bag, args.cloth, args.primitive, args.seed, args.grid,
                                   tuple(sorted(params.items())), config_label(args.grid, params),
                                   not args.in_process, args.cpu, args.fifo, not args.no_freeze_gc, args.busy_wait,
                                   args.duration)
            if args.config == "recommended":
                rec, source = hil.recommended(engine, args.cloth, args.primitive, float(rate), settings,
                                              args.tolerance_rel, args.tolerance_abs, args.budget)
                label = rec.config + (f",{config_label(None, params)}" if params else "")  # --set on top
                config = hil.with_config(config, label, rec.grid, {**rec.params, **params})
                print(f"{engine} at {rate:g} Hz: recommended `{rec.config}` from {source}: CD {rec.cd:.4f} m "
                      f"(best {rec.best_config}: {rec.best_cd:.4f} m), step p99 {rec.step_p99_ms:.3f} ms "
                      + ("under" if rec.meets_deadline else "NOT under") + f" {1e3 * args.budget / rate:g} ms")
            print(f"running {engine} at {rate:g} Hz, configuration {config.config} ...", flush=True)
            result = hil.run_hil(config, out, lockstep=not args.no_lockstep)
            results.append(result)
            print("  simulator process: " + "; ".join(result.realtime))
    rows = [r.row() for r in results]
    hil.write_results(results, out)
    print(text_table(hil_table(rows)))
    print("latency: target due on the controller's wall-clock schedule -> state back at the controller; miss: latency "
          "> 1 / rate; skipped: targets the simulator never stepped (a newer one was waiting); RTF: simulated / wall "
          "time; CPU busy: all cores, any process, during the run")
    report = write_hil_report(rows, out, out / "report")
    print(f"results: {out / 'hil.jsonl'}; report: {report} (latency over time and histogram per run)")
    return 1 if any(r.problems for r in results) else 0


def _export_recommended(args: argparse.Namespace) -> int:
    """hil --export-recommended FILE: the settings sweep's recommendation per engine, task and rate."""
    from cloth_bench_ros.report.hil import all_recommendations, provenance, recommendation_yaml
    from cloth_bench_ros.safe_io import atomic_write_text
    from cloth_bench_ros.studies.sweep import load_rows

    if not args.settings:
        raise UserError("--export-recommended needs --settings RESULTS (a settings sweep's results)")
    rows = load_rows(Path(args.settings))
    recs = all_recommendations(rows, args.tolerance_rel, args.tolerance_abs, args.budget)
    if not recs:
        raise UserError(f"settings {args.settings}: no settings-sweep rows with a stable configuration")
    atomic_write_text(Path(args.export_recommended), recommendation_yaml(
        recs, provenance(rows, args.tolerance_rel, args.tolerance_abs, args.budget, args.note or "")))
    for r in recs:
        print(f"{r.engine} {r.cloth} {r.primitive} {r.rate_hz:g} Hz: {r.config} (CD {r.cd:.4f} m, step p99 "
              f"{r.step_p99_ms:.3f} ms, deadline {'met' if r.meets_deadline else 'not met'})")
    print(f"written: {args.export_recommended}")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (the usage is in --help)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _read_transform(path: str):
    """A 4x4 matrix from a .npy file or a text file of 16 numbers (spaces, commas or newlines)."""
    import numpy as np

    try:
        if path.endswith(".npy"):
            values = np.load(path).astype(float).ravel()
        else:
            values = np.array([float(x) for x in Path(path).read_text().replace(",", " ").split()])
    except (OSError, ValueError) as exc:
        raise UserError(f"transform {path}: cannot be read ({exc})") from None
    if values.size != 16 or not np.isfinite(values).all():
        raise UserError(f"transform {path}: needs 16 finite numbers (a 4x4 matrix), found {values.size}")
    return values.reshape(4, 4)


def cmd_import(args: argparse.Namespace) -> int:
    from cloth_bench_ros.data.importer import import_dataset

    from cloth_bench_ros.core.cleaning import scene_cleaning

    transform = _read_transform(args.transform) if args.transform else None
    bags = import_dataset(Path(args.root), Path(args.out), transform=transform, progress=not args.quiet,
                          overwrite=args.overwrite, cleaning=scene_cleaning(voxel=args.voxel) if args.clean else None)
    for bag in bags:
        print(bag)
    print(f"imported {len(bags)} trial(s) into {args.out}")
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    from cloth_bench_ros.data.synth import synth_command
    from cloth_bench_ros.engines.presets import CLOTHS

    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    suffix = "" if args.reference == "mujoco" else "_" + args.reference.replace("-", "_")
    out = Path(args.out) if args.out else Path(f"{args.cloth}_{args.primitive}{suffix}")
    bag = synth_command(args.cloth, args.primitive, out, seed=args.seed, overwrite=args.overwrite,
                        progress=not args.quiet, reference=args.reference)
    print(f"synthetic bag written: {bag}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="cloth-bench", description="Sim-to-real benchmark of cloth simulators.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log the nodes' messages")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="run the node graph on a bag and print the result table")
    run.add_argument("--engine", action="append", help="engine to run (repeat for several; default mujoco)")
    run.add_argument("--rate", type=_rate, default=100.0, help="simulator rate in Hz (default 100)")
    run.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    run.add_argument("--primitive", default="dynamic", choices=PRIMITIVES, help="default dynamic")
    run.add_argument("--bag", help="rosbag2 MCAP bag to score against (default: the bundled one)")
    run.add_argument("--presets", help="directory of <engine>.yaml presets (default: config/presets)")
    run.add_argument("--seed", type=_seed, default=0, help="perturbs the initial cloth (default 0)")
    run.add_argument("--pacing", default="lockstep", choices=("lockstep", "realtime"))
    run.add_argument("--processes", action="store_true",
                     help="one OS process per node over DDS on loopback (default: all nodes in this process)")
    run.add_argument("--output", help="report directory (default results/<cloth>_<primitive>_<rate>hz_seed<seed>)")
    scoring = run.add_argument_group("scoring your own recording (see README)")
    scoring.add_argument("--topic", help="PointCloud2 topic to score (default: the project's, else the only one)")
    scoring.add_argument("--start-time", metavar="S", help="start of the motion in bag time: an absolute stamp "
                         "(>= 1e9 s) or seconds from the first message (default: targets topic, else automatic)")
    scoring.add_argument("--targets-topic", help="recorded PoseArray gripper targets whose first motion is the start")
    scoring.add_argument("--change-of-phase-frame", type=_frame, metavar="N",
                         help="last frame of the dynamic window (default: the bag's metadata, else none)")
    scoring.add_argument("--transform", metavar="FILE", help="4x4 matrix into world for every cloud, instead of tf")
    scoring.add_argument("--clean", default="auto", choices=("auto", "on", "off"),
                         help="crop, table plane, outliers (default auto: on for bags without the project's metadata)")
    scoring.add_argument("--voxel", type=_number(validation.non_negative, "voxel"), default=0.0, metavar="M",
                         help="voxel down-sampling size (default off)")
    scoring.add_argument("--table-plane", default="auto", choices=("auto", "remove", "keep"),
                         help="remove the table plane; it also removes cloth lying flat on the table "
                              "(default auto: remove for dynamic, keep for quasi_static)")
    scoring.add_argument("--align-window", type=_number(validation.positive, "align-window"), default=1.0, metavar="S",
                         help="seconds of motion the automatic alignment compares (default 1)")
    scoring.add_argument("--align-step", type=_number(validation.positive, "align-step"), default=1.0 / 30.0, metavar="S",
                         help="coarse step of the automatic alignment (default 1/30 s; refined 8x)")
    scoring.add_argument("--record-comparison", metavar="DIR", help="write a comparison bag (Foxglove/RViz)")
    scoring.add_argument("--figures", action="store_true",
                         help="qualitative figure (paper Fig. 4) and animation in the report directory")
    run.add_argument("--grid", type=_grid, help="cloth mesh NXxNZ vertices, e.g. 6x8 (default: the engine's, 11x15)")
    run.add_argument("--set", action="append", metavar="ENGINE.PARAM=VALUE",
                     help="override an engine parameter on top of the preset (repeatable)")
    run.set_defaults(func=cmd_run)

    sweep = sub.add_parser("sweep", help="many runs in parallel: engines x rates x cloths x tasks x seeds")
    sweep.add_argument("--mode", default="paper", choices=("paper", "settings"),
                       help="paper: the paper's layout (default); settings: sweep the settings that cost time")
    sweep.add_argument("--engine", action="append", help="repeat for several (default: mujoco, bullet, newton)")
    sweep.add_argument("--rate", type=_rate, action="append",
                       help="Hz, repeat for several (default 10, 100, 1000; settings mode: one rate, default 100)")
    sweep.add_argument("--cloth", action="append", help="repeat (default all three; settings mode: towel)")
    sweep.add_argument("--primitive", action="append", choices=PRIMITIVES, help="task, repeat (default both)")
    sweep.add_argument("--seeds", type=int, help="number of seeds (default 20; settings mode 2)")
    sweep.add_argument("--seed-start", type=int, default=0, help="first seed (default 0)")
    sweep.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    sweep.add_argument("--scheduler", type=_scheduler, help="run on an existing Dask cluster, e.g. tcp://127.0.0.1:8786")
    sweep.add_argument("--output", help="results directory (default results/sweep or results/settings)")
    sweep.add_argument("--bag-dir", help="directory of <cloth>_<task> or <cloth>_<trial>_<task> bags "
                                         "(default: the bundled bags)")
    sweep.add_argument("--grid", type=_grid, help="cloth mesh NXxNZ for every cell (paper mode)")
    sweep.add_argument("--set", action="append", metavar="ENGINE.PARAM=VALUE",
                       help="engine parameter override for every cell (repeatable)")
    sweep.add_argument("--pacing", default="lockstep", choices=("lockstep", "realtime"))
    sweep.add_argument("--step-per-target", action="store_true",
                       help="internal time step = 1 / rate (the paper's frequency study) instead of the preset's")
    sweep.add_argument("--keep-frames", default="first", choices=("first", "all", "none"),
                       help="seeds whose per-frame CD/HD are kept for the plots (default: the first)")
    sweep.add_argument("--axis", action="append", metavar="PARAM=V1,V2",
                       help="settings mode: an axis of the factorial sweep, e.g. grid=6x8,11x15 or "
                            "timestep=preset,0.005 (replaces the default axes)")
    sweep.add_argument("--retry-errors", action="store_true", help="run cells recorded as errors again")
    sweep.add_argument("--dry-run", action="store_true", help="count the cells and estimate the time, run nothing")
    sweep.add_argument("--no-progress", action="store_true", help="no progress bar")
    sweep.add_argument("--report", action="store_true", help="render the report into <output>/report afterwards")
    sweep.set_defaults(func=cmd_sweep)

    report = sub.add_parser("report", help="render a sweep's tables, plots and Markdown/HTML report")
    report.add_argument("results", help="results.jsonl of a sweep, or its directory")
    report.add_argument("--output", help="report directory (default <results dir>/report)")
    report.add_argument("--stress", help="stress.jsonl (or its directory) to include "
                                         "(default: stress.jsonl next to the results, if any)")
    report.add_argument("--rate", type=_rate, default=100.0, help="rate of the Table II layout (default 100 Hz)")
    report.add_argument("--fig5-cloth", default="towel", help="cloth of the Fig. 5 layout (default towel)")
    report.add_argument("--tolerance-rel", type=float, default=0.05,
                        help="settings recommendation: CD within this fraction of the best (default 0.05)")
    report.add_argument("--tolerance-abs", type=float, default=0.002,
                        help="... or within this many metres of it, whichever is larger (default 0.002)")
    report.set_defaults(func=cmd_report)

    stress = sub.add_parser("stress", help="run the suite of hard cases; reports divergence, never fails")
    stress.add_argument("--engine", action="append", help="repeat for several (default: mujoco, bullet, newton)")
    stress.add_argument("--case", action="append", help="only these cases (repeat; see --list)")
    stress.add_argument("--list", action="store_true", help="list the cases and exit")
    stress.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    stress.add_argument("--scheduler", type=_scheduler, help="run on an existing Dask cluster, e.g. tcp://127.0.0.1:8786")
    stress.add_argument("--max-wall-s", type=float, help="wall-time budget per case (default 120 s)")
    stress.add_argument("--output", help="results directory (default results/stress)")
    stress.add_argument("--no-progress", action="store_true", help="no progress bar")
    stress.set_defaults(func=cmd_stress)

    ident = sub.add_parser("identify", help="fit an engine's cloth parameters to a bag (CMA-ES and Bayesian optimisation)")
    ident.add_argument("--engine", default="mujoco", help="default mujoco")
    ident.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    ident.add_argument("--primitive", default="dynamic", choices=PRIMITIVES, help="default dynamic")
    ident.add_argument("--bag", help="rosbag2 MCAP bag to fit (default: the bundled one)")
    ident.add_argument("--sampler", default="both", choices=("cmaes", "tpe", "gp", "both"),
                       help="cmaes, tpe (Bayesian optimisation), gp (Gaussian-process BO, needs PyTorch) or both "
                            "(CMA-ES and TPE, keep the best; default)")
    ident.add_argument("--trials", type=int, default=500, help="trials per sampler (default 500, as the paper)")
    ident.add_argument("--objective", default="cd", choices=("cd", "hd"), help="metric of the task window (default cd)")
    ident.add_argument("--params", help="comma-separated parameters to fit (default: the engine's identified set)")
    ident.add_argument("--seed", type=int, default=0, help="seed of every trial (default 0)")
    ident.add_argument("--rate", type=_rate, default=100.0, help="simulator rate in Hz (default 100)")
    ident.add_argument("--grid", type=_grid, help="cloth mesh NXxNZ (default: the engine's)")
    ident.add_argument("--set", action="append", metavar="ENGINE.PARAM=VALUE", help="fixed override, not fitted")
    ident.add_argument("--span", type=float, default=10.0,
                       help="log-scale ranges reach this factor either side of the preset (default 10)")
    ident.add_argument("--max-frames", type=int, help="score only the first N frames of the window (faster)")
    ident.add_argument("--batch", type=int, help="trials in flight (default: the cluster's worker threads)")
    ident.add_argument("--validate-seeds", type=int, default=5, help="held-out seeds to validate on (default 5)")
    ident.add_argument("--bag-dir", help="other trials' bags of the cloth and task for validation")
    ident.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    ident.add_argument("--scheduler", type=_scheduler, help="run on an existing Dask cluster, e.g. tcp://127.0.0.1:8786")
    ident.add_argument("--output", help="directory (default results/identify/<engine>_<cloth>_<primitive>)")
    ident.add_argument("--no-progress", action="store_true", help="no progress bar")
    ident.set_defaults(func=cmd_identify)

    hil = sub.add_parser("hil", help="hardware in the loop: targets on the wall clock, the simulator in its own process")
    hil.add_argument("--engine", action="append", help="repeat for several (default mujoco)")
    hil.add_argument("--rate", type=_rate, action="append", help="Hz, repeat for several (default 100)")
    hil.add_argument("--config", default="preset", choices=("preset", "recommended"),
                     help="preset (with --grid/--set) or the settings sweep's recommendation for the rate")
    hil.add_argument("--settings", help="settings-sweep results for --config recommended (default results/settings; "
                                        "without a result there: config/hil_recommended.yaml)")
    hil.add_argument("--tolerance-rel", type=float, default=0.05, help="recommendation: CD within this fraction "
                                                                       "of the best (default 0.05)")
    hil.add_argument("--tolerance-abs", type=float, default=0.002, help="... or this many metres (default 0.002)")
    hil.add_argument("--deadline-budget", dest="budget", type=float, default=None,
                     help="recommendation: step p99 under this fraction of the period (default 0.5: the rest is "
                          "the round trip)")
    hil.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    hil.add_argument("--primitive", default="dynamic", choices=PRIMITIVES, help="default dynamic")
    hil.add_argument("--bag", help="rosbag2 MCAP bag (default: the bundled one)")
    hil.add_argument("--seed", type=_seed, default=0)
    hil.add_argument("--grid", type=_grid, help="cloth mesh NXxNZ (default: the engine's)")
    hil.add_argument("--set", action="append", metavar="ENGINE.PARAM=VALUE", help="engine parameter override")
    hil.add_argument("--cpu", type=int, default=-1, help="pin the simulator process to this core (default: not)")
    hil.add_argument("--fifo", type=int, default=0, metavar="PRIORITY",
                     help="ask SCHED_FIFO at this priority for the simulator and the controller (1-99; default 0: not)")
    hil.add_argument("--no-freeze-gc", action="store_true", help="keep automatic garbage collection in the simulator")
    hil.add_argument("--busy-wait", action="store_true",
                     help="the simulator polls for targets instead of sleeping (a core of its own: use with --cpu)")
    hil.add_argument("--in-process", action="store_true", help="all nodes in one process (intra-process transport)")
    hil.add_argument("--duration", type=float, default=0.0,
                     help="s of the trajectory to run (default 0: all; a shortened run is not scored)")
    hil.add_argument("--no-lockstep", action="store_true", help="skip the lockstep run that gives the CD")
    hil.add_argument("--output", help="results directory (default results/hil)")
    hil.add_argument("--export-recommended", metavar="FILE",
                     help="write the recommendation of every engine, task and rate in --settings to FILE and exit")
    hil.add_argument("--note", help="--export-recommended: a provenance note (e.g. the sweep's command)")
    hil.set_defaults(func=cmd_hil)

    traj = sub.add_parser("trajectory", help="print the quintic part of a primitive as CSV")
    traj.add_argument("--primitive", default="dynamic", choices=PRIMITIVES)
    traj.add_argument("--rate", type=_rate, default=100.0)
    traj.set_defaults(func=cmd_trajectory)

    engines = sub.add_parser("engines", help="list known engines, their availability and version")
    engines.add_argument("--warm", action="store_true",
                         help="also compile what makes an engine's first run slow (Newton: Warp's kernel cache)")
    engines.set_defaults(func=cmd_engines)

    xref = sub.add_parser("cross-reference", help="score every engine against both synthetic references")
    xref.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel; needs its "
                      "<cloth>_<task>_newton_vbd bags)")
    xref.add_argument("--primitive", action="append", choices=PRIMITIVES, help="task (repeatable; default both)")
    xref.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 per engine (default 3)")
    xref.add_argument("--rate", type=float, default=100.0, help="simulator rate in Hz (default 100)")
    xref.add_argument("--output", default="results/cross_reference",
                      help="results directory: results.jsonl (resumed) and cross_reference.md")
    xref.set_defaults(func=cmd_cross_reference)

    imp = sub.add_parser("import", help="turn the published dataset (PLY/PCD per frame) into one bag per trial")
    imp.add_argument("root", help="dataset root: <root>/<cloth>_rag_<trial>/<primitive>/cloud/<NNNNN>.ply|.pcd")
    imp.add_argument("--out", required=True, help="directory for the bags")
    imp.add_argument("--transform", help="4x4 matrix into the simulation frame (text file of 16 numbers, or .npy)")
    imp.add_argument("--overwrite", action="store_true", help="replace bags that exist")
    imp.add_argument("--clean", action="store_true",
                     help="crop to the workspace, remove the table plane and outliers (core.cleaning) before writing")
    imp.add_argument("--voxel", type=_number(validation.non_negative, "voxel"), default=0.0, metavar="M",
                     help="with --clean: voxel size (default off)")
    imp.add_argument("--quiet", action="store_true", help="no progress bar")
    imp.set_defaults(func=cmd_import)

    synth = sub.add_parser("synth", help="make a synthetic reference bag (reference simulation seen by a virtual Kinect)")
    synth.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    synth.add_argument("--primitive", default="dynamic", choices=PRIMITIVES)
    synth.add_argument("--out", help="bag directory (default <cloth>_<primitive>)")
    synth.add_argument("--seed", type=_seed, default=0, help="sensor noise and reference seed (default 0)")
    synth.add_argument("--reference", default="mujoco", choices=("mujoco", "newton-vbd"),
                       help="reference model: mujoco (config/synth.yaml, default) or newton-vbd "
                            "(config/synth_newton_vbd.yaml); default bag name <cloth>_<primitive>[_newton_vbd]")
    synth.add_argument("--overwrite", action="store_true", help="replace the bag if it exists")
    synth.add_argument("--quiet", action="store_true", help="no progress bar")
    synth.set_defaults(func=cmd_synth)

    bag = sub.add_parser("bag", help="bag tools")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True, parser_class=_Parser)
    info = bag_sub.add_parser("info", help="describe a bag: topics, frames, trial metadata")
    info.add_argument("path")
    info.set_defaults(func=cmd_bag_info)
    rewrite = bag_sub.add_parser("rewrite", help="copy a bag into the current writer's layout (rosbag2 Jazzy, "
                                 "metadata version 9, type hashes); messages and trial unchanged")
    rewrite.add_argument("src", help="bag to read")
    rewrite.add_argument("dst", help="new bag directory (must not exist or be empty)")
    rewrite.set_defaults(func=cmd_bag_rewrite)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    warnings.formatwarning = lambda message, *_: f"cloth-bench: warning: {message}\n"
    try:
        return args.func(args)
    except BrokenPipeError:  # `cloth-bench ... | head`: the reader left, nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (ClothBenchError, ValueError, OSError) as exc:  # ValueError, OSError: raised plain for bad input too
        print(f"cloth-bench: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # noqa: BLE001 - a bug: one line (the traceback with --verbose), status 1
        if args.verbose:
            raise
        print(f"cloth-bench: internal error: {type(exc).__name__}: {_one_line(exc)} "
              f"(a bug; --verbose shows the traceback)", file=sys.stderr)
        return 1


def _one_line(exc: BaseException) -> str:
    """str(exc) on one line (an OSError without a file name still says what failed)."""
    return " ".join(str(exc).split()) or type(exc).__name__


if __name__ == "__main__":
    raise SystemExit(main())
