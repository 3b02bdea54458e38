"""
Stability on hard cases: a suite of scenes that break cloth simulators (`cloth-bench stress`).

Each case drives one engine directly (make_engine + the primitive's full target trajectory,
possibly transformed: time-compressed, pushed lower, a gripper jump) with parameter overrides on
top of the engine's towel preset, and reports:

- diverged, at which step (the engine's own divergence flag: non-finite vertices, a vertex more
  than 5 m from the grippers or faster than 100 m/s, or the engine's own instability signal,
  `ClothEngine.instability_signals`), why;
- L_s over the states of the quintic part up to the divergence (as the evaluator computes it);
- the largest vertex speed max_t max_v |v_t - v_{t-1}| / dt over the run (the divergence step
  included when its state is finite);
- the step time (mean, p99, max) and the number of steps run.

A case runs in a worker process: a case the engine refuses (a project error) is an "error" row,
a worker that dies (a crash in the engine's C code) a "crashed" row, a case that exceeds its
wall-time budget is stopped and reported ("time limit"). Any other exception is a bug in the
project or an engine, never a divergence: it ends the suite (exit 1).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
import time
from typing import Sequence

from cloth_bench_ros.core.cloth_mesh import mesh_area
from cloth_bench_ros.core.metrics import StabilityAccumulator
from cloth_bench_ros.core.table import Table
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.errors import ClothBenchError, InputError, one_line
from cloth_bench_ros.safe_io import (
    atomic_write_text,
    check_output_dir,
    read_text_bounded,
    safe_name,
    UnsafeInputError,
)
from cloth_bench_ros.studies.dask_executor import default_workers, open_client, run_tasks
from cloth_bench_ros.studies.results import json_safe
from cloth_bench_ros.studies.stress_cases import case_cloth, case_inputs, case_targets, StressCase
import numpy as np
from tqdm import tqdm

STRESS_FILE = 'stress.jsonl'


def run_case(case: StressCase) -> dict:
    """Run one case to its end, its divergence or its wall-time budget; raises only on a bug."""
    row = {
        'case': case.name,
        'engine': case.engine,
        'description': case.description,
        'primitive': case.primitive,
        'rate_hz': case.rate_hz,
        'params': case.params,
        'grid': f'{case.grid[0]}x{case.grid[1]}' if case.grid else None,
        'status': 'error',
        'diverged': False,
        'diverged_at_step': None,
        'diverged_at_time': None,
        'diverged_reason': '',
        'L_s': math.nan,
        'max_vertex_speed': math.nan,
        'steps': 0,
        'step_time_mean': math.nan,
        'step_time_p99': math.nan,
        'step_time_max': math.nan,
        'wall_s': math.nan,
        'error': '',
        **{k: getattr(case, k) for k in ('task_file', 'cloth_mesh')},
    }
    start = time.perf_counter()
    engine = None
    try:
        row.update(case_inputs(case))
        left, right, q, dt = case_targets(case)
        cloth = case_cloth(case)
        params = sized_params(case.engine, {
            **load_preset(case.engine, 'towel', case.primitive), **case.params
        }, None, None, mesh_area(cloth))
        engine = make_engine(case.engine, case.rate_hz, params, cloth)
        previous = engine.reset(0, left[0], right[0]).copy()
        stability = StabilityAccumulator()
        times = []
        max_speed = 0.0
        row['status'] = 'ok'
        for k in range(1, len(left)):
            t0 = time.perf_counter()
            vertices = engine.step(left[k], right[k])
            times.append(time.perf_counter() - t0)
            vertices = np.array(vertices, dtype=float)
            if np.isfinite(vertices).all():
                max_speed = max(
                    max_speed, float(np.linalg.norm(vertices - previous, axis=1).max() / dt)
                )
            if engine.diverged:
                break
            if k >= q:
                stability.add(vertices)
            previous = vertices
            if time.perf_counter() - start > case.max_wall_s:
                row['status'] = 'time limit'
                row['error'] = (
                    f'stopped after {case.max_wall_s:g} s of wall time at step {k} of'
                    f' {len(left) - 1}'
                )
                break
        d = engine.divergence
        if d is not None:
            row.update(
                status='diverged',
                diverged=True,
                diverged_at_step=d.step,
                diverged_at_time=d.step * dt,
                diverged_reason=d.reason,
            )
        s = np.asarray(times)
        if engine.diverged and max_speed == 0.0:
            max_speed = math.nan  # the engine failed before any state could be compared
        row.update(
            L_s=stability.value,
            max_vertex_speed=max_speed,
            steps=len(times),
            step_time_mean=float(s.mean()) if len(s) else math.nan,
            step_time_p99=float(np.percentile(s, 99)) if len(s) else math.nan,
            step_time_max=float(s.max()) if len(s) else math.nan,
        )
        row['substeps'] = getattr(engine, 'substeps', None)
    except ClothBenchError as exc:  # a case the engine refuses is a result; a bug ends the suite
        row['status'] = 'error'
        row['error'] = one_line(exc, with_type=True)
    finally:
        if engine is not None:
            engine.close()
    row['wall_s'] = time.perf_counter() - start
    return row


def crashed_row(case: StressCase, message: str) -> dict:
    """Return the row of a case whose worker died (a crash in the engine's C code) on every try."""
    return {
        'case': case.name,
        'engine': case.engine,
        'description': case.description,
        'primitive': case.primitive,
        'rate_hz': case.rate_hz,
        'params': case.params,
        'status': 'crashed',
        'diverged': False,
        'error': message,
        'L_s': math.nan,
        'max_vertex_speed': math.nan,
        'step_time_mean': math.nan,
        'steps': 0,
        **{k: getattr(case, k) for k in ('task_file', 'cloth_mesh')},
    }


def run_suite(
    cases: Sequence[StressCase],
    out_dir: Path | None = None,
    workers: int | None = None,
    progress: bool = True,
    scheduler: str | None = None,
) -> list[dict]:
    """Run every case on the executor; rows in the order of `cases` (also to stress.jsonl, .md)."""
    if out_dir is not None:
        out_dir = check_output_dir(out_dir)
    rows: dict[int, dict] = {}
    index = {id(c): i for i, c in enumerate(cases)}
    bar = tqdm(total=len(cases), desc='stress', unit='case', disable=not progress)

    def done(case: StressCase, row: dict) -> None:
        rows[index[id(case)]] = row
        bar.set_postfix_str(f'{case.engine}/{case.name}: {row["status"]}', refresh=False)
        bar.update(1)

    try:
        with open_client(
            scheduler,
            workers or min(default_workers(), len(cases)),
            Path(out_dir) / 'workers.log' if out_dir is not None else None,
        ) as client:
            run_tasks(
                client,
                run_case,
                list(cases),
                on_result=done,
                on_crash=lambda case, message: done(case, crashed_row(case, message)),
            )
    finally:
        bar.close()
    ordered = [rows[i] for i in sorted(rows)]
    if out_dir is not None:
        atomic_write_text(
            Path(out_dir) / STRESS_FILE,
            ''.join(json.dumps(json_safe(r), sort_keys=True) + '\n' for r in ordered),
        )
        atomic_write_text(Path(out_dir) / 'stress.md', stress_table(ordered).markdown() + '\n')
    return ordered


def load_stress(path: Path) -> list[dict]:
    """Return the rows of a stress.jsonl, checked as untrusted input."""
    path = Path(path)
    if path.is_dir():
        path = path / STRESS_FILE
    rows = []
    for number, line in enumerate(read_text_bounded(path).splitlines(), 1):
        if not line.strip():
            continue
        where = f'{path}:{number}'
        try:
            r = json.loads(line)
        except json.JSONDecodeError:
            raise InputError(f'{where}: not a JSON line') from None
        if not isinstance(r, dict) or not all(
            k in r for k in ('case', 'engine', 'rate_hz', 'status')
        ):
            raise InputError(
                f'{where}: a stress row must be a JSON object with case, engine, rate_hz and'
                ' status'
            )
        try:
            safe_name(r['case'], 'case')
            safe_name(r['engine'], 'engine')
        except UnsafeInputError as exc:
            raise InputError(f'{where}: {exc}') from None
        if isinstance(r['rate_hz'], bool) or not isinstance(r['rate_hz'], (int, float)):
            raise InputError(f'{where}: rate_hz {r["rate_hz"]!r} is not a number')
        for k in ('L_s', 'max_vertex_speed', 'step_time_mean', 'step_time_p99', 'step_time_max'):
            if r.get(k) is None:
                r[k] = math.nan
        rows.append(r)
    return rows


def _f(value, fmt: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return '-'
    return format(value, fmt)


def stress_table(rows: Sequence[dict]) -> Table:
    """One row per case and engine; stress.md and the report both render this table."""
    headers = [
        'engine',
        'case',
        'rate Hz',
        'status',
        'diverged at step',
        'L_s (m)',
        'max vertex speed (m/s)',
        'step mean (ms)',
        'step max (ms)',
        'steps',
        'why',
    ]
    out = []
    for r in rows:
        step = r.get('diverged_at_step')
        out.append(
            [
                r['engine'],
                r['case'],
                f'{r["rate_hz"]:g}',
                r['status'],
                '-' if step is None else str(step),
                _f(r.get('L_s'), '.2e'),
                _f(r.get('max_vertex_speed'), '.3g'),
                _f(_scaled(r.get('step_time_mean'), 1e3), '.3f'),
                _f(_scaled(r.get('step_time_max'), 1e3), '.3f'),
                str(r.get('steps', 0)),
                r.get('diverged_reason') or r.get('error') or '',
            ]
        )
    return Table('stress', headers, out, 'llrlrrrrrrl')


def _scaled(value, scale: float):
    return value * scale if isinstance(value, (int, float)) else None


def verdict(rows: Sequence[dict]) -> dict[str, list[str]]:
    """Engine -> names of the cases that diverged."""
    out: dict[str, list[str]] = {}
    for r in rows:
        out.setdefault(r['engine'], [])
        if r.get('diverged'):
            out[r['engine']].append(r['case'])
    return out
