"""
What an identification leaves behind: validation, preset file and identification.json.

The validation runs through the node graph (along a task file, a recorded motion or a mesh: as
the objective's trials); identification.json holds everything the report needs,
so the report needs no Optuna.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime, timezone
import json
import math
from pathlib import Path
import platform
from typing import Any

from cloth_bench_ros.core.cloth_size import BENCHMARK_AREA, cloth_record, is_benchmark, size_text
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.engines import engine_class, engine_device
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.identify.curve import best_value, convergence, importance
from cloth_bench_ros.identify.objective import bag_task, evaluate, trial_of
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.options import FLAGS
from cloth_bench_ros.safe_io import atomic_write_text
from cloth_bench_ros.studies.cells import Cell, find_bags
from cloth_bench_ros.studies.dask_executor import run_tasks
from cloth_bench_ros.studies.recording import inputs_record
from cloth_bench_ros.studies.results import (
    append_row,
    json_safe,
    load_rows,
    RESULTS_FILE,
    rewrite_rows,
    row_key,
    stale_cells,
)
from cloth_bench_ros.sweep.study import cells_to_run, error_row, run_cell
import numpy as np
import yaml

PRESETS_DIR = 'presets'


def validation_cells(spec: IdentifySpec, fitted: dict) -> list[Cell]:
    """
    Return the validation cells: seeds other than the identification's, preset and identified.

    On its bag and the other trials' bags of the cloth and task, each with the engine's preset and
    with the identified parameters.
    """
    bags = {Path(spec.bag).resolve(): 0}
    try:
        for trial, path in find_bags(
            spec.bag_dir or Path(spec.bag).parent, spec.cloth, spec.primitive
        ):
            bags.setdefault(path.resolve(), trial)
    except ValueError:
        pass  # no other bag named after the cloth and task
    seeds = range(spec.seed + 1, spec.seed + 1 + spec.validate_seeds)
    cells = []
    for bag, trial in bags.items():
        for seed in seeds:
            for config, params in (('preset', spec.fixed), ('identified', fitted)):
                cells.append(
                    Cell(
                        spec.engine,
                        float(spec.rate_hz),
                        spec.cloth,
                        spec.primitive,
                        seed,
                        str(bag),
                        trial,
                        'paper',
                        config,
                        spec.grid,
                        tuple(sorted(params.items())),
                        cloth_size=spec.cloth_size,
                        cloth_mass=spec.cloth_mass,
                        settle=spec.settle,
                    )
                )
    return cells


def validate(client: Any, spec: IdentifySpec, fitted: dict, progress: bool) -> list[dict]:
    """Run the validation cells (resumable): per bag, preset against identified parameters."""
    if spec.cloth_mesh or bag_task(str(spec.bag), spec.task):
        return validate_along(client, spec, fitted)
    results = spec.output / RESULTS_FILE
    cells = validation_cells(spec, fitted)
    rows = load_rows(results)
    stale = stale_cells(cells, rows)
    if stale:  # more trials fitted other values (or the bag changed): validate those again
        rows = [r for r in rows if _key(r) not in stale]
        rewrite_rows(results, rows)
    todo = cells_to_run(cells, rows)
    if todo:
        run_tasks(
            client,
            run_cell,
            todo,
            on_result=lambda cell, row: append_row(results, row),
            on_crash=lambda cell, message: append_row(results, error_row(cell, message)),
            args=(str(spec.output),),
        )
    keys = {c.key() for c in cells}
    rows = [r for r in load_rows(results) if _key(r) in keys]
    out = []
    for bag in sorted({r['bag'] for r in rows}):
        entry: dict = {'bag': bag}
        for config in ('preset', 'identified'):
            sel = [r for r in rows if r['bag'] == bag and r.get('config') == config]
            values = np.array(
                [
                    r['CD' if spec.objective == 'cd' else 'HD']
                    for r in sel
                    if r.get('status') == 'ok'
                ]
            )
            entry[config] = {
                'mean': float(values.mean()) if len(values) else math.nan,
                'std': float(values.std()) if len(values) else math.nan,
                'n': len(sel),
                'ok': int(len(values)),
                'diverged': sum(r.get('status') == 'diverged' for r in sel),
            }
        out.append(entry)
    return out


def validate_along(client: Any, spec: IdentifySpec, fitted: dict) -> list[dict]:
    """
    Validate on the fitted bag's held-out seeds along its own task and cloth, as objective trials.

    A task file, a recorded motion or a mesh: the sweep's cells run the shipped tasks on grids.
    """
    seeds = range(spec.seed + 1, spec.seed + 1 + spec.validate_seeds)
    if not seeds:
        return []
    entry: dict = {'bag': str(spec.bag)}
    for config, params in (('preset', {}), ('identified', fitted)):
        trials = [replace(trial_of(spec, params, -1, config), seed=seed, also=())
                  for seed in seeds]
        results = client.gather([client.submit(evaluate, t, pure=False) for t in trials])
        values = np.array([r['value'] for r in results if r['status'] == 'ok'])
        entry[config] = {
            'mean': float(values.mean()) if len(values) else math.nan,
            'std': float(values.std()) if len(values) else math.nan,
            'n': len(results),
            'ok': int(len(values)),
            'diverged': sum(r['status'] == 'diverged' for r in results),
        }
    return [entry]


def _key(row: dict) -> tuple:
    return row_key(row)


def bag_source(bag: Any, limit: int = 120) -> str:
    """Return the head of a bag's `source` (what made it: a reference and its rate), or ''."""
    try:
        with BagReader(Path(bag)) as reader:
            trial = reader.trial
    except (ClothBenchError, OSError):  # a bag that cannot say: the provenance names its path
        return ''
    source = (trial.source if trial is not None else '') or ''
    head = source.split(' (')[0].split(';')[0].strip()
    return head if len(head) <= limit else head[: limit - 3] + '...'


def provenance_text(spec: IdentifySpec, summary: dict, version: str) -> str:
    """Return the preset file's provenance: what was fitted against what, how, when and where."""
    params = ', '.join(f'{k} = {v:.6g}' for k, v in summary['params'].items())
    fixed = ', '.join(f'{k} = {v}' for k, v in spec.fixed.items() if k != 'device')
    fixed = f'fixed {fixed}; ' if fixed else ''
    trials = ', '.join(f'{s} {r["trials"]}' for s, r in summary['per_sampler'].items())
    fidelity = getattr(spec, 'fidelity', FLAGS['fidelity'].default)
    if fidelity != 'full':  # the budget counts trials stopped at a rung: say how many
        pruned = sum(r.get('pruned', 0) for r in summary['per_sampler'].values())
        trials += f'; multi-fidelity {fidelity}, {pruned} stopped at a rung'
    held_out = '; '.join(
        f'{Path(v["bag"]).name}: preset {v["preset"]["mean"]:.4f} m, identified'
        f' {v["identified"]["mean"]:.4f} m ({v["identified"]["ok"]} seeds)'
        for v in summary.get('validation', [])
    )
    held_out = f'Held-out seeds ({spec.objective.upper()}): {held_out}. ' if held_out else ''
    made_by = bag_source(spec.bag)
    return (
        f'Identified by cloth-bench identify against bag {spec.bag} ({spec.cloth},'
        f' {spec.primitive}{"; " + made_by if made_by else ""}): '
        f'minimised {spec.objective.upper()} of the task window to {summary["value"]:.6g} m '
        f'(the preset: {summary["preset_value"]:.6g} m) with {summary["best_sampler"]} '
        f'(trials: {trials}; seed {spec.seed}, '
        f'{spec.rate_hz:g} Hz, grid {"x".join(map(str, spec.grid)) if spec.grid else "default"}'
        f', {spec.settle} settle'
        f'{", first " + str(spec.max_frames) + " frames" if spec.max_frames else ""}); fitted'
        f' {params}; '
        f'{fixed}'
        f"the other values are the preset's. {held_out}Engine version {version}"
        f' on device {engine_device(spec.engine, spec.fixed)}; '
        f'{datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")} on '
        f'{platform.machine()}, {platform.python_implementation()} {platform.python_version()}.'
    )


def write_outputs(spec: IdentifySpec, base: dict, summary: dict) -> Path:
    """<output>/presets/<engine>.yaml (config/presets format) and <output>/identification.json."""
    version = engine_class(spec.engine).version() or 'unknown'
    values = {**base, **{k: float(v) for k, v in summary['params'].items()}}
    values.pop('device', None)  # a preset is of the cloth; the device is in the provenance
    provenance = provenance_text(spec, summary, version)
    size = getattr(spec, 'cloth_size', None)
    if size is not None and not is_benchmark(size) and 'mass' in values:  # for the benchmark's:
        values['mass'] = float(values['mass']) * BENCHMARK_AREA / (size[0] * size[1])
        provenance += (
            f" Fitted on a {size_text(size)} cloth; its mass is restated for the benchmark's"
            f' {size_text(None)} at the same mass per area (run --cloth-size gives it back).'
        )
    document = {
        'engine': spec.engine,
        'engine_version': str(version),
        'provenance': provenance,
        'presets': {spec.cloth: {spec.primitive: values}},
    }
    folder = spec.output / PRESETS_DIR
    folder.mkdir(parents=True, exist_ok=True)
    preset = folder / f'{spec.engine}.yaml'
    atomic_write_text(preset, yaml.safe_dump(document, sort_keys=False, width=100))
    summary['preset_file'] = str(Path(PRESETS_DIR) / preset.name)
    summary['engine_version'] = str(version)
    summary['device'] = engine_device(spec.engine, spec.fixed)
    summary['date'] = datetime.now(timezone.utc).isoformat(timespec='seconds')
    summary['machine'] = platform.machine()  # no host name: preset files get shipped
    atomic_write_text(
        spec.output / 'identification.json', json.dumps(json_safe(summary), indent=1) + '\n'
    )
    return preset


def _inputs(spec: IdentifySpec) -> dict:
    """Return the task of each bag, the mesh, the gripper frames and the table height."""
    tasks = [bag_task(str(b), spec.task) for b in (spec.bag, *spec.also)]
    return inputs_record(spec.primitive, tasks, spec.cloth_mesh, spec.gripper_frames,
                         spec.table_z)


def summarise(
    spec: IdentifySpec,
    space: dict,
    base: dict,
    before: dict,
    studies: dict,
    best: str,
    validation: list,
) -> dict:
    """Return what identification.json keeps: problem, samplers' results, choice, validation."""
    return {
        'engine': spec.engine,
        'cloth': spec.cloth,
        'primitive': spec.primitive,
        'bag': str(spec.bag),
        'objective': spec.objective,
        'seed': spec.seed,
        'rate_hz': spec.rate_hz,
        'grid': list(spec.grid) if spec.grid else None,
        **cloth_record(spec.cloth_size, spec.cloth_mass),
        'fixed': spec.fixed,
        'max_frames': spec.max_frames,
        'fidelity': spec.fidelity,
        'settle': spec.settle,
        **_inputs(spec),
        'space': {n: [d.low, d.high, d.log] for n, d in space.items()},
        'samplers': list(studies),
        'best_sampler': best,
        'params': dict(studies[best].best_params),
        'value': best_value(studies[best]),
        'preset_params': {n: base.get(n) for n in space},
        'preset_value': before['value'],
        'preset_status': before['status'],
        'per_sampler': {
            s: {
                'value': best_value(st),
                'params': st.best_params if math.isfinite(best_value(st)) else {},
                'convergence': convergence(st),
                'importance': importance(st),
                'trials': len(convergence(st)),
                'pruned': sum(t.state.name == 'PRUNED' for t in st.get_trials(deepcopy=False)),
            }
            for s, st in studies.items()
        },
        'validation': validation,
    }
