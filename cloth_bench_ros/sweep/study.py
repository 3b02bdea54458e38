"""
Sweeps: many pipeline runs on the Dask executor, one JSON line per finished cell.

A cell (studies/cells.py) is one run: `run_direct` in lockstep (the node graph's metrics without
its nodes), `run_pipeline` in realtime. Results go to <out>/results.jsonl, appended as each cell
finishes (an interrupted sweep loses at most the cells in flight), under the directory's lock (a
second study there refuses with one line). A new run over the same directory skips every cell
already present: it resumes. A diverged run is a result (NaN metrics, status "diverged"); input
a cell cannot run on (a project error: an unreadable bag, refused parameters) is an "error" row;
any other exception is a bug and ends the sweep (exit 1); a worker that dies mid-cell is replaced
and the cell runs again elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from itertools import product
import math
import os
from pathlib import Path
import sys
import time
import traceback
from typing import Sequence

from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import SUFFIX_TASK
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.engines.presets import CLOTHS, load_preset, PresetSet
# re-exported: the studies' one vocabulary
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.errors import ClothBenchError, InputError
from cloth_bench_ros.metric_choice import METRICS
from cloth_bench_ros.options import FLAGS, OPTIONS
from cloth_bench_ros.safe_io import check_output_dir
from cloth_bench_ros.studies.cells import (  # noqa: F401
    Cell,
    config_label,
    DEFAULT_CLOTHS,
    DEFAULT_ENGINES,
    DEFAULT_PRIMITIVES,
    DEFAULT_RATES,
    DEFAULT_SEEDS,
    estimated_cost,
    find_bags,
    paper_cells,
    PRESET,
    settings_cells,
    SETTINGS_RATE,
    SETTINGS_SEEDS,
    with_inputs,
)
from cloth_bench_ros.studies.dask_executor import default_workers, open_client, run_tasks
from cloth_bench_ros.studies.direct import run_direct
from cloth_bench_ros.studies.results import (  # noqa: F401
    append_row,
    bag_fingerprint,
    cloth_fields,
    drop_superseded,
    json_safe,
    load_rows,
    ResultRow,
    RESULTS_FILE,
    ResultsError,
    ResultsLock,
    row_key,
    SCORED_WITH,
    stale_cells,
    with_kept_scoring,
)
from cloth_bench_ros.studies.run_config import RunConfig
from cloth_bench_ros.studies.run_pipeline import run_pipeline
from cloth_bench_ros.sweep.parsing import (  # noqa: F401  (re-exported)
    parse_grid,
    parse_overrides,
    parse_settings_axes,
    parse_value,
)
from tqdm import tqdm

# -------------------------------------------------------------------------------------- rows


def _nan(value):
    return math.nan if value is None else value


def summary_row(cell: Cell, summary: dict) -> dict:
    """Return the flat results row of one finished run."""
    m = summary['engines'][cell.engine]
    suffix = load_task(cell.primitive, cell.task_file or None).suffix  # the task's window
    keyed = SUFFIX_TASK[suffix]  # the shipped task whose metric keys that window has
    trial = summary['run'].get('trial') or {}
    st, lat = m['step_time'], m['latency']
    beside = {  # the metrics beside the paper's, under their task-free keys (metric_choice)
        x.key: _nan(m.get(x.summary_key(keyed)))
        for x in METRICS.values()
        if x.summary_key(keyed) in m
    }
    return {
        **beside,
        'CD': _nan(m.get(f'CD_{suffix}')),
        'HD': _nan(m.get(f'HD_{suffix}')),
        'task_suffix': suffix,
        'L_s': _nan(m.get('L_s')),
        'step_count': st['count'],
        'step_time_mean': st['mean'],
        'step_time_p50': st['p50'],
        'step_time_p99': st['p99'],
        'step_time_max': st['max'],
        'latency_count': lat['count'],
        'latency_mean': lat['mean'],
        'latency_p50': lat['p50'],
        'latency_p99': lat['p99'],
        'latency_max': lat['max'],
        'deadline_misses': m.get('deadline_misses'),
        'skipped_targets': m.get('skipped_targets'),
        'real_time_factor': m.get('real_time_factor'),
        'frames_scored': m.get('frames_scored'),
        'frames_in_window': m.get('frames_in_window'),
        'diverged': bool(m.get('diverged')),
        'diverged_at_step': m.get('diverged_at_step'),
        'diverged_at_time': m.get('diverged_at_time'),
        'diverged_reason': m.get('diverged_reason') or '',
        'change_of_phase_frame': trial.get('change_of_phase_frame'),
        'real_frames': summary['real'].get('frames'),
        'unpaired_frames': summary['real'].get('unpaired_frames'),
        'run_wall_time': summary['run'].get('wall_time'),
    }


def _cell_fields(cell: Cell) -> dict:
    fields = {
        'mode': cell.mode,
        'config': cell.config,
        'engine': cell.engine,
        'rate_hz': float(cell.rate_hz),
        'cloth': cell.cloth,
        'primitive': cell.primitive,
        'trial': int(cell.trial),
        'seed': int(cell.seed),
        'pacing': cell.pacing,
        'device': cell.device,
        **{name: getattr(cell, name) for name in SCORED_WITH},  # how it is computed
        'model': cell.model,
        'bag': cell.bag,
        'grid': f'{cell.grid[0]}x{cell.grid[1]}' if cell.grid else None,
        'params': cell.params,
        'bag_fingerprint': bag_fingerprint(cell.bag),
        'task_file': cell.task_file,
        'cloth_mesh': cell.cloth_mesh,
    }
    if cell.reference:  # a cross-reference cell names the synthetic reference it is scored against
        fields['reference'] = cell.reference
    if cell.preset_set != 'default':
        fields['presets'] = cell.preset_set
    fields.update(cloth_fields(cell))
    return fields


def _substeps(cell: Cell) -> int | None:
    """Return the internal steps per target of engines with `timestep` and `substeps`."""
    try:
        config = engine_class(cell.engine).validate_params(
            {**load_preset(cell.engine, cell.cloth, cell.primitive), **cell.params}
        )
    except ClothBenchError:  # an engine or parameters the cell's error row names already
        return None
    if 'timestep' not in config:
        return None
    return max(
        int(config.get('substeps', 1)),
        math.ceil(1.0 / cell.rate_hz / float(config['timestep']) - 1e-9),
    )


def error_row(cell: Cell, message: str, wall_s: float = math.nan) -> dict:
    """Return the row of a cell whose run failed."""
    return {
        **_cell_fields(cell),
        'status': 'error',
        'error': message,
        'diverged': False,
        'CD': math.nan,
        'HD': math.nan,
        'L_s': math.nan,
        'cell_wall_s': wall_s,
        'frames_csv': None,
    }


def cell_config(cell: Cell, output_dir: Path | None) -> RunConfig:
    """Return the run a cell stands for."""
    return RunConfig(
        bag=Path(cell.bag), engines=[cell.engine], rate_hz=cell.rate_hz, cloth=cell.cloth,
        primitive=cell.primitive, seed=cell.seed, pacing=cell.pacing, output_dir=output_dir,
        engine_params={cell.engine: cell.params}, grid=cell.grid, cloth_size=cell.cloth_size,
        cloth_mass=cell.cloth_mass, all_metrics=cell.all_metrics, settle=cell.settle,
        task=cell.task_file, cloth_mesh=cell.cloth_mesh or None,
    )


def run_cell(cell: Cell, out_dir: str) -> dict:
    """Run one cell (in a worker process); input it cannot run on is an error row, a bug raises."""
    start = time.perf_counter()
    frames_dir = Path(out_dir) / 'frames' / cell.ident() if cell.keep_frames else None
    try:
        config = cell_config(cell, frames_dir)
        # Lockstep cells run at the physics limit (engine, trajectory and evaluator called
        # directly, metrics equal to the node graph's); realtime cells need the graph's clocks.
        summary = run_direct(config) if cell.pacing == 'lockstep' else run_pipeline(config)
        if summary is None:
            raise RuntimeError('the pipeline ended without a summary')
        row = {**_cell_fields(cell), **summary_row(cell, summary)}
        row['status'] = 'diverged' if row['diverged'] else 'ok'
        row['error'] = ''
    except ClothBenchError as exc:  # input this cell cannot run on is a row; a bug ends the sweep
        last = traceback.extract_tb(exc.__traceback__)[-1:] if exc.__traceback__ else []
        where = f' ({Path(last[0].filename).name}:{last[0].lineno})' if last else ''
        return error_row(cell, f'{type(exc).__name__}: {exc}{where}', time.perf_counter() - start)
    row['substeps'] = _substeps(cell)
    # Step times are wall times: the machine's load tells whether other work slowed them down.
    row['load_avg_1min'] = os.getloadavg()[0] if hasattr(os, 'getloadavg') else None
    row['cpu_count'] = os.cpu_count()
    row['frames_csv'] = (
        str((frames_dir / 'frames.csv').relative_to(out_dir)) if frames_dir else None
    )
    row['cell_wall_s'] = time.perf_counter() - start
    return row


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


def cells_to_run(
    cells: Sequence[Cell], existing: Sequence[dict], retry_errors: bool = False
) -> list[Cell]:
    """
    Return the cells not yet in `existing`, seed by seed, the longest first within a seed.

    ResultsError (one line) if a row of one of these cells was made with other inputs.
    """
    stale = list(stale_cells(cells, existing).values())
    if stale:
        raise ResultsError(
            f'{len(stale)} cells of this study are already in the results with other inputs, e.g.'
            f' {stale[0]}: the preset set or the bag changed since; give another --output'
            ' (or remove those rows) to run them again'
        )
    done = {row_key(r) for r in existing if not retry_errors or r.get('status') != 'error'}
    todo: dict[tuple, Cell] = {}
    for cell in cells:
        if cell.key() not in done:
            todo.setdefault(cell.key(), cell)
    # Seed by seed (an interrupted sweep has whole seeds), the longest cells first within one.
    return sorted(todo.values(), key=lambda c: (c.seed, -estimated_cost(c)))


def run_sweep(
    cells: Sequence[Cell],
    out_dir: Path,
    workers: int | None = None,
    progress: bool = True,
    retry_errors: bool = False,
    desc: str = 'sweep',
    scheduler: str | None = None,
) -> SweepOutcome:
    """Run every cell not yet in <out_dir>/results.jsonl on the executor, appending its row."""
    out_dir = check_output_dir(out_dir)
    results = out_dir / RESULTS_FILE
    with ResultsLock(out_dir, desc):
        existing = load_rows(results)
        todo = cells_to_run(cells, existing, retry_errors)
        drop_superseded(results, todo, existing)  # rows computed otherwise: run again
        outcome = SweepOutcome(results, len(cells), len(cells) - len(todo), 0, 0, 0, 0.0)
        start = time.perf_counter()
        bar = tqdm(
            total=len(todo),
            desc=desc,
            unit='cell',
            disable=not progress,
            file=sys.stderr,
            dynamic_ncols=True,
        )

        def record(row: dict) -> None:
            append_row(results, row)
            outcome.rows.append(row)
            outcome.ran += 1
            outcome.errors += row.get('status') == 'error'
            outcome.diverged += row.get('status') == 'diverged'
            bar.set_postfix(diverged=outcome.diverged, errors=outcome.errors, refresh=False)
            bar.update(1)

        try:
            if todo:
                with open_client(scheduler, workers, out_dir / 'workers.log') as client:
                    run_tasks(
                        client,
                        run_cell,
                        todo,
                        on_result=lambda cell, row: record(row),
                        on_crash=lambda cell, message: record(error_row(cell, message)),
                        args=(str(out_dir),),
                    )
        finally:
            bar.close()
            outcome.wall_s = time.perf_counter() - start
    return outcome


# ------------------------------------------------------------------------------ planning


@dataclass
class SweepPlan:
    """What `cloth-bench sweep` was asked for, checked; `cells()` builds the cells."""

    mode: str = FLAGS['sweep_mode'].default
    engines: Sequence[str] = DEFAULT_ENGINES
    rates: Sequence[float] = ()
    cloths: Sequence[str] = ()
    primitives: Sequence[str] = DEFAULT_PRIMITIVES
    n_seeds: int | None = None
    seed_start: int = 0
    bag_dir: Path | None = None
    grid: tuple[int, int] | None = None
    overrides: dict = field(default_factory=dict)
    pacing: str = OPTIONS['pacing'].default
    step_per_target: bool = False
    keep_frames: str = FLAGS['keep_frames'].default  # first | all | none
    axes: Sequence[str] = ()  # settings mode: "name=v1,v2" strings
    presets: PresetSet | None = None  # a preset set instead of the shipped presets
    all_metrics: bool = False  # every metric in every cell, not only the paper's CD/HD
    left_out: list[str] = field(default_factory=list)  # 'engine cloth task' the set lacks
    settle: str = FULL  # the settle phase of every cell (engines/settle.py)

    def seeds(self) -> list[int]:
        settings = self.mode == 'settings'
        n = (
            self.n_seeds
            if self.n_seeds is not None
            else (SETTINGS_SEEDS if settings else DEFAULT_SEEDS)
        )
        if n < 1:
            raise InputError(f'--seeds must be at least 1, got {n}')
        if self.seed_start < 0:
            raise InputError(f'--seed-start must be >= 0, got {self.seed_start}')
        return list(range(self.seed_start, self.seed_start + n))

    def cells(self) -> list[Cell]:
        """Return the sweep's cells; ValueError (one line) on a combination that makes no sense."""
        if self.settle != FULL and self.pacing != 'lockstep':
            raise InputError('--settle fast runs lockstep cells only: the node graph of '
                             '--pacing realtime settles in full')
        return [replace(cell, settle=self.settle) for cell in self._cells()]

    def _cells(self) -> list[Cell]:
        settings = self.mode == 'settings'
        cloths = list(self.cloths) or (['towel'] if settings else list(DEFAULT_CLOTHS))
        for cloth in cloths:
            if cloth not in CLOTHS:
                raise InputError(f'unknown cloth {cloth!r} (valid: {", ".join(CLOTHS)})')
        primitives = list(self.primitives) or list(DEFAULT_PRIMITIVES)
        gaps = self._preset_gaps(cloths, primitives)
        if gaps and not (self.cloths and self.primitives):
            # A set covering part of the default cloths and tasks: sweep what it covers.
            if len(gaps) == len(self.engines) * len(cloths) * len(primitives):
                raise InputError(
                    f'--presets {self.presets.name if self.presets else ""} has no values for'
                    f' {", ".join(cloths)} ({", ".join(primitives)})'
                )
            self.left_out = [' '.join(gap) for gap in sorted(gaps)]
            return [
                cell
                for engine, cloth, primitive in product(self.engines, cloths, primitives)
                if (engine, cloth, primitive) not in gaps
                for cell in replace(
                    self, engines=[engine], cloths=[cloth], primitives=[primitive]
                ).cells()
            ]
        seeds = self.seeds()
        if settings:
            if len(self.rates) > 1:
                raise InputError('--mode settings runs at one rate: give --rate once')
            if self.grid:
                raise InputError(
                    '--mode settings sweeps the grid itself: use --axis grid=6x8,11x15 instead of'
                    ' --grid'
                )
            axes = parse_settings_axes(self.axes) if self.axes else None
            return settings_cells(
                self.engines,
                (list(self.rates) or [SETTINGS_RATE])[0],
                cloths,
                primitives,
                seeds,
                self.bag_dir,
                axes,
                self.overrides,
                self.presets,
                self.all_metrics,
            )
        if self.axes:
            raise InputError('--axis is for --mode settings')
        keep = {'first': seeds[:1], 'all': seeds, 'none': []}[self.keep_frames]
        return paper_cells(
            self.engines,
            list(self.rates) or list(DEFAULT_RATES),
            cloths,
            primitives,
            seeds,
            self.bag_dir,
            self.grid,
            self.overrides,
            self.pacing,
            self.step_per_target,
            keep,
            self.presets,
            self.all_metrics,
        )

    def _preset_gaps(self, cloths: list[str], primitives: list[str]) -> set[tuple[str, str, str]]:
        """Return the (engine, cloth, task) a named preset set has no values for."""
        if self.presets is None or self.presets.is_default:
            return set()
        gaps = set()
        for engine, cloth, primitive in product(self.engines, cloths, primitives):
            try:
                model = self.overrides.get(engine, {}).get('model')
                load_preset(engine, cloth, primitive, self.presets.directory, model)
            except EngineError:
                gaps.add((engine, cloth, primitive))
        return gaps


def estimate(cells: Sequence[Cell], out_dir: Path, workers: int | None) -> str:
    """One line: cells left in out_dir and the time they need (`sweep --dry-run`)."""
    todo = cells_to_run(cells, load_rows(Path(out_dir) / RESULTS_FILE))
    cost = sum(estimated_cost(c) for c in todo)
    workers = workers or default_workers()
    return (
        f'cloth-bench sweep: {len(cells)} cells, {len(cells) - len(todo)} already in '
        f'{Path(out_dir) / RESULTS_FILE}; about {cost / 60:.0f} core-minutes left, '
        f'{cost / 60 / workers:.0f} min on {workers} workers'
    )
