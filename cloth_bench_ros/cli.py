"""`cloth-bench`: the command-line front door (run, trajectory, engines, bag)."""

from __future__ import annotations

import argparse
import logging
import sys
import time
import warnings
from pathlib import Path

from cloth_bench_ros.core.trajectory import PRIMITIVES


class UserError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""


def _rate(text: str) -> float:
    try:
        rate = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"rate {text!r} is not a number") from None
    if not rate > 0 or rate == float("inf"):
        raise argparse.ArgumentTypeError(f"rate must be > 0 Hz, got {text}")
    return rate


def check_bag(bag: Path) -> None:
    """Fail early, with one line naming the bag, unless its first PointCloud2 frame decodes."""
    from cloth_bench_ros.data.bag import BagReader
    from cloth_bench_ros.data.messages import deserialize
    from cloth_bench_ros.core.pointcloud2 import read_xyz

    reader = BagReader(bag)
    topic = reader.cloud_topic()
    first = next(reader.raw_messages([topic]), None)
    if first is None:
        raise UserError(f"bag {bag}: no PointCloud2 message on {topic} could be read")
    try:
        read_xyz(deserialize(first[3], first[1]))
    except ValueError as exc:
        raise UserError(f"bag {bag}, topic {topic}: {exc}") from None


def cmd_run(args: argparse.Namespace) -> int:
    from cloth_bench_ros.engines import engine_class
    from cloth_bench_ros.engines.presets import CLOTHS, load_preset
    from cloth_bench_ros.paths import bundled_bag
    from cloth_bench_ros.studies.pipeline import RunConfig, run_pipeline
    from cloth_bench_ros.report.run_report import result_table

    engines = args.engine or ["mujoco"]
    for name in engines:
        engine_class(name)
    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    presets = Path(args.presets) if args.presets else None
    for name in engines:  # a malformed preset file or bad value fails here, in one line
        load_preset(name, args.cloth, args.primitive, presets)
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    check_bag(bag)
    out = Path(args.output) if args.output else Path("results") / f"{args.cloth}_{args.primitive}_{int(args.rate)}hz_seed{args.seed}"
    config = RunConfig(bag=bag, engines=engines, rate_hz=args.rate, cloth=args.cloth, primitive=args.primitive,
                       seed=args.seed, pacing=args.pacing, output_dir=out,
                       engine_params=_overrides(getattr(args, "set", None), engines), grid=getattr(args, "grid", None), presets_dir=presets)
    summary = run_pipeline(config)
    print(f"cloth-bench run: {args.cloth} {args.primitive} at {args.rate:g} Hz, seed {args.seed}, bag {bag}")
    print(result_table(summary))
    real = summary["real"]
    print(f"real frames: {real['frames']} ({real['empty_frames_skipped']} empty skipped, "
          f"{real['nan_points_dropped']} NaN points dropped, {real['unpaired_frames']} unpaired, "
          f"{real['irregular_intervals']} intervals not at 30 Hz)")
    print(f"report: {out}/summary.json, {out}/frames.csv")
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
    from cloth_bench_ros.data.bag import describe

    print(describe(Path(args.path)))
    return 0


def _grid(text: str) -> tuple[int, int]:
    from cloth_bench_ros.studies.sweep import parse_grid

    try:
        return parse_grid(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _overrides(specs: list[str] | None, engines: list[str] | None = None) -> dict[str, dict]:
    """--set engine.param=value (repeatable) -> {engine: {param: value}}, checked against the schemas."""
    from cloth_bench_ros.engines import engine_class
    from cloth_bench_ros.studies.sweep import parse_overrides

    overrides = parse_overrides(specs)
    for engine, params in overrides.items():
        if engines is not None and engine not in engines:
            raise UserError(f"--set {engine}.…: engine {engine} is not part of this run ({', '.join(engines)})")
        engine_class(engine).validate_params(params)
    return overrides


def _available_engines() -> list[str]:
    from cloth_bench_ros.engines import known_engines

    return [i.name for i in known_engines() if i.available]


def cmd_sweep(args: argparse.Namespace) -> int:
    from cloth_bench_ros.studies import sweep as sw
    from cloth_bench_ros.engines.presets import CLOTHS

    settings = args.mode == "settings"
    engines = args.engine or [e for e in sw.DEFAULT_ENGINES if e in _available_engines()]
    cloths = args.cloth or (["towel"] if settings else list(sw.DEFAULT_CLOTHS))
    for cloth in cloths:
        if cloth not in CLOTHS:
            raise UserError(f"unknown cloth {cloth!r} (valid: {', '.join(CLOTHS)})")
    primitives = args.primitive or list(sw.DEFAULT_PRIMITIVES)
    n_seeds = args.seeds if args.seeds is not None else (sw.SETTINGS_SEEDS if settings else sw.DEFAULT_SEEDS)
    if n_seeds < 1:
        raise UserError(f"--seeds must be at least 1, got {n_seeds}")
    seeds = list(range(args.seed_start, args.seed_start + n_seeds))
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    overrides = _overrides(args.set, engines)
    bag_dir = Path(args.bag_dir) if args.bag_dir else None
    out = Path(args.output) if args.output else Path("results") / ("settings" if settings else "sweep")
    if settings:
        if args.rate and len(args.rate) > 1:
            raise UserError("--mode settings runs at one rate: give --rate once")
        if args.grid:
            raise UserError("--mode settings sweeps the grid itself: use --axis grid=6x8,11x15 instead of --grid")
        axes = sw.parse_settings_axes(args.axis) if args.axis else None
        cells = sw.settings_cells(engines, (args.rate or [sw.SETTINGS_RATE])[0], cloths, primitives, seeds,
                                  bag_dir, axes, overrides)
    else:
        if args.axis:
            raise UserError("--axis is for --mode settings")
        keep = {"first": seeds[:1], "all": seeds, "none": []}[args.keep_frames]
        cells = sw.paper_cells(engines, args.rate or list(sw.DEFAULT_RATES), cloths, primitives, seeds, bag_dir,
                               args.grid, overrides, args.pacing, args.step_per_target, keep)
    if args.dry_run:
        done = {sw.row_key(r) for r in sw.load_rows(out / sw.RESULTS_FILE)}
        todo = [c for c in cells if c.key() not in done]
        cost = sum(sw.estimated_cost(c) for c in todo)
        workers = args.workers or sw.default_workers()
        print(f"cloth-bench sweep: {len(cells)} cells, {len(cells) - len(todo)} already in {out / sw.RESULTS_FILE}; "
              f"about {cost / 60:.0f} core-minutes left, {cost / 60 / workers:.0f} min on {workers} workers")
        return 0
    print(f"cloth-bench sweep ({args.mode}): {len(engines)} engines x {len(set(c.rate_hz for c in cells))} rates x "
          f"{len(cloths)} cloths x {len(primitives)} tasks x {len(seeds)} seeds"
          + (f" x {len({c.config for c in cells})} configurations" if settings else "")
          + f" = {len(cells)} cells -> {out / sw.RESULTS_FILE}", flush=True)
    outcome = sw.run_sweep(cells, out, args.workers, progress=not args.no_progress, retry_errors=args.retry_errors)
    print(f"sweep: {outcome.ran} cells run in {outcome.wall_s:.1f} s ({outcome.skipped} already done), "
          f"{outcome.diverged} diverged, {outcome.errors} errors; results: {outcome.results}")
    if args.report:
        return _render(out, out / "report", None, 100.0, "towel", 0.05, 0.002)
    return 0


def _render(results: Path, out: Path, stress: Path | None, rate: float, cloth: str, tol_rel: float,
            tol_abs: float) -> int:
    from cloth_bench_ros.report.document import render_report
    from cloth_bench_ros.studies.stress import STRESS_FILE, load_stress
    from cloth_bench_ros.studies.sweep import RESULTS_FILE, load_rows

    results = Path(results)
    results_file = results / RESULTS_FILE if results.is_dir() else results
    if not results_file.is_file():
        raise UserError(f"results {results}: no {RESULTS_FILE} there (run `cloth-bench sweep` first)")
    rows = load_rows(results_file)
    if not rows:
        raise UserError(f"results {results_file}: holds no result rows")
    if stress is None and (results_file.parent / STRESS_FILE).is_file():
        stress = results_file.parent / STRESS_FILE
    if stress is not None and not Path(stress).exists():
        raise UserError(f"stress results {stress}: no such file or directory")
    stress_rows = load_stress(Path(stress)) if stress is not None else None
    outcome = render_report(rows, results_file.parent, out, stress_rows, rate, cloth, tol_rel, tol_abs)
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
    from cloth_bench_ros.studies.stress import default_cases, run_suite, stress_table, verdict

    engines = args.engine or [e for e in ("mujoco", "bullet", "newton") if e in _available_engines()]
    for name in engines:
        from cloth_bench_ros.engines import engine_class

        engine_class(name)
    cases = default_cases(engines)
    if args.list:
        for c in cases:
            print(f"{c.engine:<8} {c.name:<24} {c.description}")
        return 0
    if args.case:
        names = {c.name for c in cases}
        unknown = sorted(set(args.case) - names)
        if unknown:
            raise UserError(f"unknown stress case {', '.join(unknown)} (known: {', '.join(sorted(names))})")
        cases = [c for c in cases if c.name in args.case]
    if args.max_wall_s is not None:
        from dataclasses import replace

        cases = [replace(c, max_wall_s=args.max_wall_s) for c in cases]
    out = Path(args.output) if args.output else Path("results") / "stress"
    rows = run_suite(cases, out, args.workers, progress=not args.no_progress)
    print(stress_table(rows))
    for engine, diverged in verdict(rows).items():
        n = sum(r["engine"] == engine for r in rows)
        print(f"{engine}: {len(diverged)} of {n} cases diverged" + (f" ({', '.join(diverged)})" if diverged else ""))
    print(f"stress: {out}/stress.jsonl, {out}/stress.md")
    return 0


def cmd_hil(args: argparse.Namespace) -> int:
    from cloth_bench_ros.studies import sweep as sw
    from cloth_bench_ros.engines import engine_class
    from cloth_bench_ros.engines.presets import CLOTHS
    from cloth_bench_ros.paths import bundled_bag

    engine_class(args.engine)
    if args.cloth not in CLOTHS:
        raise UserError(f"unknown cloth {args.cloth!r} (valid: {', '.join(CLOTHS)})")
    bag = Path(args.bag) if args.bag else bundled_bag(args.cloth, args.primitive)
    check_bag(bag)
    overrides = _overrides(args.set, [args.engine])
    out = Path(args.output) if args.output else Path("results") / "hil"
    out.mkdir(parents=True, exist_ok=True)
    rates = args.rate or [100.0]
    params = overrides.get(args.engine, {})
    print(f"cloth-bench hil: {args.engine}, {args.cloth} {args.primitive}, targets paced by the wall clock; bag {bag}")
    header = (f"{'engine':<8} {'rate Hz':>8} {'steps':>6} {'lat p50 ms':>10} {'lat p99 ms':>10} {'lat max ms':>10} "
              f"{'deadline misses':>18} {'RTF':>6} {'step p50 ms':>11} {'step p99 ms':>11}  status")
    rows = []
    for rate in rates:
        cell = sw.Cell(args.engine, float(rate), args.cloth, args.primitive, args.seed, str(bag), 0, "paper",
                       sw.config_label(args.grid, params), args.grid, tuple(sorted(params.items())), "realtime", True)
        row = sw.run_cell(cell, str(out))
        rows.append(row)
        if row["status"] == "error":
            raise UserError(f"hil at {rate:g} Hz failed: {row['error']}")
    keys = {sw.row_key(r) for r in rows}
    kept = [r for r in sw.load_rows(out / sw.RESULTS_FILE) if sw.row_key(r) not in keys]
    (out / sw.RESULTS_FILE).write_text("")
    for r in kept + rows:
        sw.append_row(out / sw.RESULTS_FILE, r)
    print(header)
    print("-" * len(header))
    for r in rows:
        n = r.get("latency_count") or 0
        misses = r.get("deadline_misses") or 0
        print(f"{r['engine']:<8} {r['rate_hz']:>8g} {n:>6} {r['latency_p50'] * 1e3:>10.3f} {r['latency_p99'] * 1e3:>10.3f} "
              f"{r['latency_max'] * 1e3:>10.3f} {f'{misses} ({100 * misses / max(n, 1):.1f} %)':>18} "
              f"{r['real_time_factor']:>6.3f} {r['step_time_p50'] * 1e3:>11.3f} {r['step_time_p99'] * 1e3:>11.3f}  "
              + (f"diverged at step {r['diverged_at_step']}" if r["diverged"] else "ok"))
    print("latency: the target's due time on the wall-clock schedule (first target + k / rate) -> state received, "
          "so falling behind counts; miss: latency > 1 / rate; RTF: simulated / wall time")
    print(f"results: {out / sw.RESULTS_FILE} (render with `cloth-bench report {out}`)")
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

    transform = _read_transform(args.transform) if args.transform else None
    bags = import_dataset(Path(args.root), Path(args.out), transform=transform, progress=not args.quiet,
                          overwrite=args.overwrite)
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
    run.add_argument("--seed", type=int, default=0, help="perturbs the initial cloth (default 0)")
    run.add_argument("--pacing", default="lockstep", choices=("lockstep", "realtime"))
    run.add_argument("--output", help="report directory (default results/<cloth>_<primitive>_<rate>hz_seed<seed>)")
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
    sweep.add_argument("--workers", type=int, help="worker processes (default: all cores)")
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
    stress.add_argument("--workers", type=int, help="worker processes (default: all cores)")
    stress.add_argument("--max-wall-s", type=float, help="wall-time budget per case (default 120 s)")
    stress.add_argument("--output", help="results directory (default results/stress)")
    stress.add_argument("--no-progress", action="store_true", help="no progress bar")
    stress.set_defaults(func=cmd_stress)

    hil = sub.add_parser("hil", help="hardware-in-the-loop timing: one run with targets paced by the wall clock")
    hil.add_argument("--engine", default="mujoco", help="default mujoco")
    hil.add_argument("--rate", type=_rate, action="append", help="Hz, repeat for several (default 100)")
    hil.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    hil.add_argument("--primitive", default="dynamic", choices=PRIMITIVES, help="default dynamic")
    hil.add_argument("--bag", help="rosbag2 MCAP bag (default: the bundled one)")
    hil.add_argument("--seed", type=int, default=0)
    hil.add_argument("--grid", type=_grid, help="cloth mesh NXxNZ (default: the engine's)")
    hil.add_argument("--set", action="append", metavar="ENGINE.PARAM=VALUE", help="engine parameter override")
    hil.add_argument("--output", help="results directory (default results/hil)")
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
    imp.add_argument("--quiet", action="store_true", help="no progress bar")
    imp.set_defaults(func=cmd_import)

    synth = sub.add_parser("synth", help="make a synthetic reference bag (reference simulation seen by a virtual Kinect)")
    synth.add_argument("--cloth", default="towel", help="towel, chequered or linen (default towel)")
    synth.add_argument("--primitive", default="dynamic", choices=PRIMITIVES)
    synth.add_argument("--out", help="bag directory (default <cloth>_<primitive>)")
    synth.add_argument("--seed", type=int, default=0, help="sensor noise and reference seed (default 0)")
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
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    warnings.formatwarning = lambda message, *_: f"cloth-bench: warning: {message}\n"
    from cloth_bench_ros.data.bag import BagError

    try:
        return args.func(args)
    except (UserError, ValueError, OSError, BagError) as exc:
        print(f"cloth-bench: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
