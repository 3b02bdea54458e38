"""Sweeps: many pipeline runs in parallel worker processes, one JSON line per finished cell.

A cell is one `run_pipeline` call: (engine, rate, cloth, task, trial bag, seed) plus a named
engine configuration (grid and parameter overrides). Two kinds of sweep build cells:

- paper (`cloth-bench sweep`): engines x rates x cloths x tasks x trials x seeds with the
  engines' presets, the layout of the paper's Table II and Fig. 5;
- settings (`cloth-bench sweep --mode settings`): per engine, a factorial sweep over the settings
  that cost time (mesh resolution, self-collision, internal time step, solver iterations) at one
  rate, to find the cheapest configuration within a tolerance of the most accurate one.

Results go to <out>/results.jsonl, appended by the parent process as each cell finishes (so an
interrupted sweep loses at most the cells in flight). A new run over the same directory skips
every cell already present: sweeps are resumable. A diverged run is a result (NaN metrics,
status "diverged"); an exception inside a cell is an "error" row; a worker process that dies
(e.g. a segfault in an engine) is retried once, then recorded as an error row.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
import time
import traceback
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from itertools import product
from pathlib import Path
from typing import Callable, Iterable, Sequence

RESULTS_FILE = "results.jsonl"
DEFAULT_RATES = (10.0, 100.0, 1000.0)
DEFAULT_ENGINES = ("mujoco", "bullet", "newton")
DEFAULT_CLOTHS = ("towel", "chequered", "linen")
DEFAULT_PRIMITIVES = ("dynamic", "quasi_static")
DEFAULT_SEEDS = 20
PRESET = "preset"

# Settings sweep (mode "settings"): the settings that cost time, each axis a list of values;
# None means "the preset's value". The cells are the full factorial product.
DEFAULT_SETTINGS_AXES: dict[str, list] = {
    "grid": [(6, 8), (11, 15), (16, 22)],
    "self_collision": [False, True],
    "timestep": [None, 0.005, 0.01],
    "solver_iterations": [None, 5],
}
SETTINGS_RATE = 100.0
SETTINGS_SEEDS = 2


# ------------------------------------------------------------------------------------ cells


@dataclass(frozen=True)
class Cell:
    """One pipeline run of a sweep."""

    engine: str
    rate_hz: float
    cloth: str
    primitive: str
    seed: int
    bag: str
    trial: int = 0
    mode: str = "paper"
    config: str = PRESET  # name of the engine configuration (grid + overrides)
    grid: tuple[int, int] | None = None
    overrides: tuple[tuple[str, object], ...] = ()  # sorted (parameter, value) pairs
    pacing: str = "lockstep"
    keep_frames: bool = False  # write summary.json + frames.csv of this run (per-frame plots)

    def key(self) -> tuple:
        """What makes a cell unique in a results file (resume compares these)."""
        return (self.mode, self.config, self.engine, float(self.rate_hz), self.cloth, self.primitive,
                int(self.trial), int(self.seed), self.pacing)

    def ident(self) -> str:
        """A file-system-safe name of the cell."""
        text = (f"{self.mode}_{self.config}_{self.engine}_{self.rate_hz:g}hz_{self.cloth}_{self.primitive}"
                f"_t{self.trial}_s{self.seed}_{self.pacing}")
        return re.sub(r"[^A-Za-z0-9_.=-]+", "-", text)

    @property
    def params(self) -> dict:
        return dict(self.overrides)


def row_key(row: dict) -> tuple:
    """Cell.key() of a results row."""
    return (row.get("mode", "paper"), row.get("config", PRESET), row["engine"], float(row["rate_hz"]),
            row["cloth"], row["primitive"], int(row.get("trial", 0)), int(row["seed"]),
            row.get("pacing", "lockstep"))


def config_label(grid: tuple[int, int] | None, overrides: dict) -> str:
    """A canonical name of a configuration: "preset" or "grid=6x8,param=value,...". """
    parts = []
    if grid is not None:
        parts.append(f"grid={grid[0]}x{grid[1]}")
    for name in sorted(overrides):
        value = overrides[name]
        if isinstance(value, bool):
            value = "on" if value else "off"
        parts.append(f"{name}={value:g}" if isinstance(value, float) else f"{name}={value}")
    return ",".join(parts) or PRESET


_BAG_NAME = r"^{cloth}(?:_(\d+))?_{primitive}$"


def find_bags(bag_dir: Path | None, cloth: str, primitive: str) -> list[tuple[int, Path]]:
    """(trial, path) of every bag for a cloth and task in `bag_dir` (default: the bundled bags).

    Names `<cloth>_<primitive>` (the bundled ones) and `<cloth>_<trial>_<primitive>` (the
    importer's) both count. ValueError if there is none.
    """
    from cloth_bench_ros.paths import share_dir

    base = Path(bag_dir) if bag_dir is not None else share_dir("bags")
    pattern = re.compile(_BAG_NAME.format(cloth=re.escape(cloth), primitive=re.escape(primitive)))
    found = []
    if base.is_dir():
        for path in sorted(base.iterdir()):
            m = pattern.match(path.name)
            if m and path.is_dir():
                found.append((int(m.group(1)) if m.group(1) else _bag_trial(path), path))
    if not found:
        raise ValueError(f"bag directory {base}: no bag named {cloth}_{primitive} or {cloth}_<trial>_{primitive}")
    return sorted(found)


def _bag_trial(path: Path) -> int:
    from cloth_bench_ros.data.bag import BagReader

    try:
        trial = BagReader(path).trial
    except Exception:  # an unreadable bag is reported by the cell that runs it
        return 0
    return int(trial.trial) if trial is not None else 0


def _check_engines(engines: Iterable[str], overrides: dict[str, dict]) -> None:
    """EngineError (a ValueError) on an unknown engine or a bad override, before any work."""
    from cloth_bench_ros.engines import engine_class

    for name in engines:
        cls = engine_class(name)
        cls.validate_params(overrides.get(name, {}))


def paper_cells(engines: Sequence[str] = DEFAULT_ENGINES, rates: Sequence[float] = DEFAULT_RATES,
                cloths: Sequence[str] = DEFAULT_CLOTHS, primitives: Sequence[str] = DEFAULT_PRIMITIVES,
                seeds: Sequence[int] = tuple(range(DEFAULT_SEEDS)), bag_dir: Path | None = None,
                grid: tuple[int, int] | None = None, overrides: dict[str, dict] | None = None,
                pacing: str = "lockstep", step_per_target: bool = False,
                keep_frames_seeds: Iterable[int] | None = None) -> list[Cell]:
    """The cells of the paper's layout. step_per_target: internal time step = 1 / rate, one
    engine step per target (the paper's frequency study), instead of the preset's time step.
    keep_frames_seeds: seeds whose per-frame scores are kept (default: the first seed)."""
    overrides = overrides or {}
    _check_engines(engines, overrides)
    keep = set(keep_frames_seeds) if keep_frames_seeds is not None else set(list(seeds)[:1])
    cells = []
    for cloth, primitive in product(cloths, primitives):
        for trial, bag in find_bags(bag_dir, cloth, primitive):
            for engine, rate, seed in product(engines, rates, seeds):
                params = dict(overrides.get(engine, {}))
                label = config_label(grid, params)
                if step_per_target:
                    params.update(timestep=1.0 / float(rate), substeps=1)
                    label = "step=1/rate" if label == PRESET else f"{label},step=1/rate"
                cells.append(Cell(engine, float(rate), cloth, primitive, int(seed), str(bag), trial, "paper",
                                  label, grid, tuple(sorted(params.items())), pacing, seed in keep))
    return cells


def settings_cells(engines: Sequence[str] = DEFAULT_ENGINES, rate: float = SETTINGS_RATE,
                   cloths: Sequence[str] = ("towel",), primitives: Sequence[str] = DEFAULT_PRIMITIVES,
                   seeds: Sequence[int] = tuple(range(SETTINGS_SEEDS)), bag_dir: Path | None = None,
                   axes: dict[str, list] | None = None, overrides: dict[str, dict] | None = None) -> list[Cell]:
    """Factorial sweep over the settings that cost time, per engine, at one rate.

    axes: parameter -> values ("grid" -> [(nx, nz), ...]); None as a value means the preset's.
    An axis naming a parameter that an engine does not have is skipped for that engine.
    """
    from cloth_bench_ros.engines import engine_class

    axes = dict(DEFAULT_SETTINGS_AXES if axes is None else axes)
    overrides = overrides or {}
    _check_engines(engines, overrides)
    grids = axes.pop("grid", [None])
    cells = []
    for engine in engines:
        schema = {p.name for p in engine_class(engine).params}
        names = [n for n in axes if n in schema]
        combos = []
        for grid in grids:
            for values in product(*(axes[n] for n in names)):
                params = dict(overrides.get(engine, {}))
                params.update({n: v for n, v in zip(names, values) if v is not None})
                engine_class(engine).validate_params(params)
                parts = [f"grid={grid[0]}x{grid[1]}" if grid else "grid=default"]
                for n, v in zip(names, values):
                    shown = PRESET if v is None else ("on" if v is True else "off" if v is False else f"{v:g}")
                    parts.append(f"{n}={shown}")
                fixed = {k: v for k, v in overrides.get(engine, {}).items() if k not in names}
                if fixed:  # --set values shared by every configuration are part of its name
                    parts.append(config_label(None, fixed))
                combos.append((",".join(parts), tuple(grid) if grid else None, tuple(sorted(params.items()))))
        for cloth, primitive in product(cloths, primitives):
            for trial, bag in find_bags(bag_dir, cloth, primitive):
                for (label, grid, params), seed in product(combos, seeds):
                    cells.append(Cell(engine, float(rate), cloth, primitive, int(seed), str(bag), trial,
                                      "settings", label, grid, params, "lockstep", False))
    return cells


def estimated_cost(cell: Cell) -> float:
    """A rough cost of a cell in seconds of one core (for ordering; measured on 11 x 15 at 100 Hz)."""
    duration = 7.4 if cell.primitive == "dynamic" else 17.0  # settle phase + quintic part, s
    params = cell.params
    nx, nz = cell.grid or (11, 15)
    timestep = float(params.get("timestep", 0.002 if cell.engine == "mujoco" else 0.0025))
    internal_steps = duration * max(cell.rate_hz, 1.0 / timestep)
    per_internal_step = 0.4e-3 * (nx * nz / 165.0) * {"bullet": 1.7, "newton": 5.0}.get(cell.engine, 1.0)
    return internal_steps * per_internal_step + duration * cell.rate_hz * 0.25e-3 + 1.0


# -------------------------------------------------------------------------------------- rows


def _nan(value):
    return math.nan if value is None else value


def summary_row(cell: Cell, summary: dict) -> dict:
    """The flat results row of one finished run."""
    m = summary["engines"][cell.engine]
    suffix = "d" if cell.primitive == "dynamic" else "q"
    trial = summary["run"].get("trial") or {}
    st, lat = m["step_time"], m["latency"]
    return {
        "CD": _nan(m.get(f"CD_{suffix}")), "HD": _nan(m.get(f"HD_{suffix}")), "task_suffix": suffix,
        "L_s": _nan(m.get("L_s")),
        "step_count": st["count"], "step_time_mean": st["mean"], "step_time_p50": st["p50"],
        "step_time_p99": st["p99"], "step_time_max": st["max"],
        "latency_count": lat["count"], "latency_mean": lat["mean"], "latency_p50": lat["p50"],
        "latency_p99": lat["p99"], "latency_max": lat["max"],
        "deadline_misses": m.get("deadline_misses"), "real_time_factor": m.get("real_time_factor"),
        "frames_scored": m.get("frames_scored"), "frames_in_window": m.get("frames_in_window"),
        "diverged": bool(m.get("diverged")), "diverged_at_step": m.get("diverged_at_step"),
        "diverged_at_time": m.get("diverged_at_time"), "diverged_reason": m.get("diverged_reason") or "",
        "change_of_phase_frame": trial.get("change_of_phase_frame"),
        "real_frames": summary["real"].get("frames"), "unpaired_frames": summary["real"].get("unpaired_frames"),
        "run_wall_time": summary["run"].get("wall_time"),
    }


def _cell_fields(cell: Cell) -> dict:
    return {
        "mode": cell.mode, "config": cell.config, "engine": cell.engine, "rate_hz": float(cell.rate_hz),
        "cloth": cell.cloth, "primitive": cell.primitive, "trial": int(cell.trial), "seed": int(cell.seed),
        "pacing": cell.pacing, "bag": cell.bag, "grid": f"{cell.grid[0]}x{cell.grid[1]}" if cell.grid else None,
        "params": cell.params,
    }


def _substeps(cell: Cell) -> int | None:
    """Internal steps per target of engines with `timestep` and `substeps` parameters."""
    try:
        from cloth_bench_ros.engines import engine_class
        from cloth_bench_ros.engines.presets import load_preset

        config = engine_class(cell.engine).validate_params(
            {**load_preset(cell.engine, cell.cloth, cell.primitive), **cell.params})
    except Exception:
        return None
    if "timestep" not in config:
        return None
    return max(int(config.get("substeps", 1)), math.ceil(1.0 / cell.rate_hz / float(config["timestep"]) - 1e-9))


def error_row(cell: Cell, message: str, wall_s: float = math.nan) -> dict:
    return {**_cell_fields(cell), "status": "error", "error": message, "diverged": False,
            "CD": math.nan, "HD": math.nan, "L_s": math.nan, "cell_wall_s": wall_s, "frames_csv": None}


def run_cell(cell: Cell, out_dir: str) -> dict:
    """Run one cell (in a worker process); never raises for a failure of the run itself."""
    start = time.perf_counter()
    frames_dir = Path(out_dir) / "frames" / cell.ident() if cell.keep_frames else None
    try:
        from cloth_bench_ros.engines import engine_class
        from cloth_bench_ros.studies.pipeline import RunConfig, run_pipeline

        config = RunConfig(bag=Path(cell.bag), engines=[cell.engine], rate_hz=cell.rate_hz, cloth=cell.cloth,
                           primitive=cell.primitive, seed=cell.seed, pacing=cell.pacing, output_dir=frames_dir,
                           engine_params={cell.engine: cell.params}, grid=cell.grid)
        summary = run_pipeline(config)
        if summary is None:
            raise RuntimeError("the pipeline ended without a summary")
        row = {**_cell_fields(cell), **summary_row(cell, summary)}
        row["status"] = "diverged" if row["diverged"] else "ok"
        row["error"] = ""
        row["engine_version"] = engine_class(cell.engine).version()
    except Exception as exc:  # a failure of this cell is a result row, never a crash of the sweep
        last = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
        where = f" ({Path(last[0].filename).name}:{last[0].lineno})" if last else ""
        return error_row(cell, f"{type(exc).__name__}: {exc}{where}", time.perf_counter() - start)
    row["substeps"] = _substeps(cell)
    # Step times are wall times: the machine's load tells whether other work slowed them down.
    row["load_avg_1min"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    row["cpu_count"] = os.cpu_count()
    row["frames_csv"] = str((frames_dir / "frames.csv").relative_to(out_dir)) if frames_dir else None
    row["cell_wall_s"] = time.perf_counter() - start
    return row


# ---------------------------------------------------------------------------- results file


def _json_safe(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


NUMERIC_FIELDS = ("CD", "HD", "L_s", "step_time_mean", "step_time_p50", "step_time_p99", "step_time_max",
                  "latency_mean", "latency_p50", "latency_p99", "latency_max", "real_time_factor", "cell_wall_s")


def load_rows(path: Path) -> list[dict]:
    """Rows of a results.jsonl (null metrics back to NaN); a torn last line is skipped."""
    path = Path(path)
    if path.is_dir():
        path = path / RESULTS_FILE
    rows = []
    if not path.exists():
        return rows
    with path.open() as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue  # a line cut short by an interrupted sweep: that cell runs again
            for name in NUMERIC_FIELDS:
                if name in row and row[name] is None:
                    row[name] = math.nan
            rows.append(row)
    return rows


def append_row(path: Path, row: dict) -> None:
    """One JSON line; after a line torn by an interrupted sweep, on a line of its own."""
    path = Path(path)
    torn = False
    if path.exists() and path.stat().st_size > 0:
        with path.open("rb") as f:
            f.seek(-1, os.SEEK_END)
            torn = f.read(1) != b"\n"
    with path.open("a") as f:
        f.write(("\n" if torn else "") + json.dumps(_json_safe(row), sort_keys=True) + "\n")
        f.flush()


# ---------------------------------------------------------------------------------- runner


@dataclass
class SweepOutcome:
    results: Path
    cells: int  # cells of the sweep
    skipped: int  # already in the results file
    ran: int  # finished now
    errors: int
    diverged: int
    wall_s: float
    rows: list = field(default_factory=list)  # rows finished now


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


def run_parallel(func: Callable, items: Sequence, workers: int, on_result: Callable,
                 on_crash: Callable, args: tuple = (), log_path: Path | None = None) -> None:
    """func(item, *args) for every item in a pool of `workers` spawned processes.

    on_result(item, result) as each finishes (in the parent). A worker that dies (e.g. a
    segfault in an engine) takes its pool down: the items that were in flight are then run
    again one at a time, each alone in a fresh process, so that the one that kills its process
    is found and gets on_crash(item, message) while the others get their results; then the
    remaining items continue in a new pool. What the workers (and the engines' C code in them)
    print goes to log_path (default: discarded), not to the terminal of the progress bar.
    """
    import multiprocessing

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")  # one core per worker: the engines are single-threaded
    context = multiprocessing.get_context("spawn")
    initargs = (str(log_path or os.devnull),)
    pending = deque(items)
    in_flight_limit = max(1, workers) * 2

    def isolated(item) -> None:
        with ProcessPoolExecutor(max_workers=1, mp_context=context, initializer=_quiet_worker,
                                 initargs=initargs) as alone:
            try:
                result = alone.submit(func, item, *args).result()
            except BrokenProcessPool:
                on_crash(item, "the worker process died while running this case")
                return
            except Exception as exc:
                on_crash(item, f"{type(exc).__name__}: {exc}")
                return
        on_result(item, result)

    while pending:
        suspects = []
        executor = ProcessPoolExecutor(max_workers=max(1, workers), mp_context=context,
                                       initializer=_quiet_worker, initargs=initargs)
        futures: dict = {}
        try:
            while pending or futures:
                while pending and not suspects and len(futures) < in_flight_limit:
                    item = pending.popleft()
                    try:
                        futures[executor.submit(func, item, *args)] = item
                    except BrokenProcessPool:
                        suspects.append(item)
                if not futures:
                    break
                done, _ = wait(futures, return_when=FIRST_COMPLETED)
                for future in done:
                    item = futures.pop(future)
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        suspects.append(item)
                        continue
                    except Exception as exc:  # pickling problems and the like
                        on_crash(item, f"{type(exc).__name__}: {exc}")
                        continue
                    on_result(item, result)
        except BaseException:
            executor.shutdown(wait=False, cancel_futures=True)
            raise
        executor.shutdown(wait=True, cancel_futures=True)
        for item in suspects:
            isolated(item)


def _quiet_worker(log_path: str) -> None:
    """Worker output (Python and C: MuJoCo's and Bullet's warnings) goes to log_path; the parent
    owns the terminal and its progress bar."""
    import logging
    import warnings

    try:
        fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
    except OSError:
        pass
    logging.basicConfig(level=logging.WARNING, format=f"[worker {os.getpid()}] %(levelname)s %(message)s")
    warnings.simplefilter("ignore")


def run_sweep(cells: Sequence[Cell], out_dir: Path, workers: int | None = None, progress: bool = True,
              retry_errors: bool = False, desc: str = "sweep") -> SweepOutcome:
    """Run every cell not yet in <out_dir>/results.jsonl, appending rows as they finish."""
    from tqdm import tqdm

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = out_dir / RESULTS_FILE
    existing = load_rows(results)
    done = {row_key(r) for r in existing if not retry_errors or r.get("status") != "error"}
    seen: set = set()
    todo = []
    for cell in cells:
        if cell.key() in done or cell.key() in seen:
            continue
        seen.add(cell.key())
        todo.append(cell)
    # Seed by seed (an interrupted sweep has whole seeds), the longest cells first within one.
    todo.sort(key=lambda c: (c.seed, -estimated_cost(c)))
    outcome = SweepOutcome(results, len(cells), len(cells) - len(todo), 0, 0, 0, 0.0)
    start = time.perf_counter()
    bar = tqdm(total=len(todo), desc=desc, unit="cell", disable=not progress, file=sys.stderr,
               dynamic_ncols=True)

    def record(row: dict) -> None:
        append_row(results, row)
        outcome.rows.append(row)
        outcome.ran += 1
        outcome.errors += row.get("status") == "error"
        outcome.diverged += row.get("status") == "diverged"
        bar.set_postfix(diverged=outcome.diverged, errors=outcome.errors, refresh=False)
        bar.update(1)

    try:
        if todo:
            run_parallel(run_cell, todo, workers or default_workers(),
                         on_result=lambda cell, row: record(row),
                         on_crash=lambda cell, message: record(error_row(cell, message)),
                         args=(str(out_dir),), log_path=out_dir / "workers.log")
    finally:
        bar.close()
        outcome.wall_s = time.perf_counter() - start
    return outcome


def parse_settings_axes(specs: Sequence[str]) -> dict[str, list]:
    """Axes from "name=v1,v2,..." strings ("grid=6x8,11x15"; "preset" for the preset's value)."""
    axes: dict[str, list] = {}
    for spec in specs:
        name, sep, values = spec.partition("=")
        if not sep or not name or not values:
            raise ValueError(f"settings axis {spec!r} is not name=value1,value2,...")
        parsed = []
        for text in values.split(","):
            text = text.strip()
            if name == "grid":
                parsed.append(parse_grid(text))
            elif text == PRESET:
                parsed.append(None)
            else:
                parsed.append(parse_value(text))
        axes[name.strip()] = parsed
    return axes


def parse_grid(text: str) -> tuple[int, int]:
    """"11x15" -> (11, 15); ValueError on anything else."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) < 2 or int(m.group(2)) < 2:
        raise ValueError(f"grid {text!r} is not NXxNZ with at least 2 vertices per side (e.g. 11x15)")
    return int(m.group(1)), int(m.group(2))


def parse_value(text: str):
    """A parameter value from the command line: bool, int, float or string."""
    low = text.strip().lower()
    if low in ("true", "on", "yes"):
        return True
    if low in ("false", "off", "no"):
        return False
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text.strip()


def parse_overrides(specs: Sequence[str] | None) -> dict[str, dict]:
    """{"engine": {"param": value}} from "engine.param=value" strings."""
    out: dict[str, dict] = {}
    for spec in specs or ():
        lhs, sep, value = spec.partition("=")
        engine, dot, param = lhs.partition(".")
        if not sep or not dot or not engine or not param:
            raise ValueError(f"--set {spec!r} is not engine.param=value (e.g. mujoco.self_collision=true)")
        out.setdefault(engine.strip(), {})[param.strip()] = parse_value(value)
    return out
