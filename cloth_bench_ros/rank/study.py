"""
`cloth-bench rank`: the engines fitted to a user's cloth, scored on trials they were not fitted to.

The protocol, the same for every engine: the recordings' trials (rank.trials) grouped by
cloth and task; per group, leave-one-trial-out folds (5 folds above 5 trials); per engine and
fold, identification (identify.study, the same sampler and budget for every engine) on the
training trials, the objective being the mean over them; then the held-out trial scored with the
identified parameters and with the preset on `seeds` seeds (the evaluator's core, as `run`
scores); step times at each rate; the cross-task check where a cloth's two tasks were recorded;
the floor (the distance between the group's real trials). Trials of recorded motions (each
recording's own, its trial bag carrying its task file) pool in their cloth's group, and a held-out
trial of a motion its fold was not fitted on is the cross-motion check. Every finished
identification and cell is kept (the identifications' journals, `cells.jsonl`): the same
command resumes.
The ranking itself is rank.answer's (the statistics of rank.ranking); this module runs the cells.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import hashlib
import json
from pathlib import Path
import shutil
import sys
from typing import Any, Callable, Sequence

from cloth_bench_ros.core.cloth_size import cloth_record, grid_vertices
from cloth_bench_ros.core.surface_metrics import SURFACE_REVISION
from cloth_bench_ros.data.bag_layout import fingerprint
from cloth_bench_ros.data.replay import ReplayOptions
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.identify.errors import ProblemChanged
from cloth_bench_ros.identify.objective import evaluate, Trial
from cloth_bench_ros.identify.problem import resolved_device, simulated_model
from cloth_bench_ros.identify.shared_simulations import pool_cells, split_pooled
from cloth_bench_ros.identify.spec import IdentifySpec, OBJECTIVES
from cloth_bench_ros.identify.study import identify, SUMMARY_FILE
from cloth_bench_ros.metric_choice import DEFAULT_METRIC
from cloth_bench_ros.options import FLAGS, OPTIONS
from cloth_bench_ros.rank.errors import RankError
from cloth_bench_ros.rank.trials import (
    floor,
    prepare_trials,
    RankTrial,
    recordings_of,
    reference_error,
)
from cloth_bench_ros.safe_io import check_output_dir
from cloth_bench_ros.studies.cloth import cloth_name
from cloth_bench_ros.studies.dask_executor import ClusterOnDemand
from cloth_bench_ros.studies.recording import inputs_key, inputs_record
from cloth_bench_ros.studies.results import append_row, ResultsLock
from distributed import as_completed
from tqdm import tqdm

DEFAULT_ENTRANTS: tuple[tuple[str, dict], ...] = (
    ('mujoco', {}),
    ('bullet', {}),
    ('newton', {'model': 'xpbd'}),
)
RATES = FLAGS['rates'].default
MAX_FOLDS = 5
CELLS_FILE = 'cells.jsonl'
SHARED_FILE = 'simulations.jsonl'


@dataclass
class RankSpec:
    """What to rank, on what, how."""

    recordings: Sequence[str]
    output: Path
    entrants: Sequence[tuple[str, dict]] = DEFAULT_ENTRANTS
    replay: ReplayOptions = field(default_factory=ReplayOptions)  # cloth, task, topic, ...
    # identification budget per sampler (AUTO: from the convergence curve)
    trials: int = FLAGS['trials'].default
    # both (CMA-ES too) doubles the cost (docs/identification.md)
    sampler: str = FLAGS['sampler'].default
    seeds: int = FLAGS['rank_seeds'].default  # held-out seeds 1..seeds
    rate_hz: float = OPTIONS['rate_hz'].default
    rates: Sequence[float] = RATES
    grid: tuple[int, int] | None = None
    metric: str = DEFAULT_METRIC  # the ranking metric; cd/hd: the objective too
    max_frames: int | None = None
    fixed: dict = field(default_factory=dict)  # per engine: overrides on every entrant of it
    # identification's: full, or prune (identify/fidelity.py)
    fidelity: str = FLAGS['fidelity'].default
    cloth_size: tuple[float, float] | None = None  # (W, L) m; None: the benchmark's 0.5 x 0.7
    cloth_mass: float | None = None  # kg, the cloth's (not fitted); None: the preset's per area
    settle: str = FULL  # the settle phase (engines/settle.py): full (the paper's) or fast
    tasks: Sequence[str] = ()  # per recording: its recorded motion's task file ('' : replay.task)
    cloth_mesh: str = ''  # --cloth-mesh; '': the grid
    gripper_frames: str = ''
    table_z: float | None = None


def entrant_key(engine: str, overrides: dict) -> str:
    """Return an entrant's file-safe name, e.g. newton-xpbd."""
    return '-'.join([engine, *(str(v) for _, v in sorted(overrides.items()))])


def folds(n: int) -> list[list[int]]:
    """Return the held-out trial indices of each fold: one each up to MAX_FOLDS, else 5 folds."""
    if n <= MAX_FOLDS:
        return [[i] for i in range(n)]
    return [list(range(k, n, MAX_FOLDS)) for k in range(MAX_FOLDS)]


def groups_of(trials: Sequence[RankTrial], say: Callable[[str], None]) -> dict:
    """Return (cloth, primitive) -> trials of groups with two usable trials or more."""
    groups: dict[tuple[str, str], list[RankTrial]] = {}
    for t in trials:
        groups.setdefault((t.cloth, t.primitive), []).append(t)
    kept = {}
    for (cloth, primitive), members in sorted(groups.items()):
        if len(members) < 2:
            say(f'{cloth} {primitive}: {len(members)} usable trial; left out (ranking needs 2)')
        else:
            kept[(cloth, primitive)] = members
    return kept


def _read_cells(path: Path) -> dict[str, dict]:
    rows = {}
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                row = json.loads(line)
                if row.get('status') != 'error':  # a failed cell kept by an older version: again
                    rows[row['key']] = row
            except (ValueError, KeyError, TypeError, AttributeError):
                continue  # a torn last line: that cell runs again
    return rows


def _identify(spec: RankSpec, engine: str, overrides: dict, train: list[RankTrial],
              group: list[RankTrial], out: Path, cluster: ClusterOnDemand, progress: bool,
              say: Callable[[str], None]) -> dict:
    """
    Return the identified parameters of one fold (resumed or reused when already done).

    The folds of an entrant share their simulations (identify.shared_simulations), kept beside
    the folds' folders: the same values, engine time spent once per parameter set. A fold whose
    journal was fitted to another problem (identify.problem) is identified afresh. Every
    fold runs on the command's one cluster.
    """
    bags = [t.bag for t in train]
    stamp = json.loads(json.dumps({
        'bags': bags, 'data': [fingerprint(Path(b)) for b in bags], 'trials': spec.trials,
        'sampler': spec.sampler, 'grid': spec.grid, 'metric': objective(spec),
        'rate_hz': spec.rate_hz, 'max_frames': spec.max_frames,
        'fixed': {**spec.fixed.get(engine, {}), **overrides}, 'fidelity': spec.fidelity,
        'settle': spec.settle, **cloth_record(spec.cloth_size, spec.cloth_mass),
        'inputs': [_inputs_key(spec, t) for t in train],
        'model': simulated_model(engine, train[0].cloth, train[0].primitive, spec.cloth_size,
                                 spec.cloth_mass, {**spec.fixed.get(engine, {}), **overrides}),
    }))
    done = out / SUMMARY_FILE
    if done.exists():
        try:
            summary = json.loads(done.read_text())
            if summary.get('rank_stamp') == stamp:
                return summary
        except ValueError:
            pass  # damaged: identify again (its journal keeps the finished trials)
    ident = IdentifySpec(
        engine, train[0].cloth, train[0].primitive, Path(bags[0]), out, spec.sampler,
        spec.trials, objective(spec), (), 0, spec.rate_hz, spec.grid,
        {**spec.fixed.get(engine, {}), **overrides}, validate_seeds=0,
        max_frames=spec.max_frames, also=tuple(bags[1:]), fidelity=spec.fidelity,
        cloth_size=spec.cloth_size, cloth_mass=spec.cloth_mass, settle=spec.settle,
        pool=tuple(t.bag for t in group), shared=out.parent / SHARED_FILE,
        task=spec.replay.task, cloth_mesh=spec.cloth_mesh,
    )
    try:
        summary = identify(ident, progress=progress, client=cluster.client()).summary
    except ProblemChanged as exc:  # its trials recorded again, another grid, rate, preset...
        say(f'{out.name}: its trials or settings changed since it was identified '
            f'({exc.changed}): identified again')
        shutil.rmtree(out)
        summary = identify(ident, progress=progress, client=cluster.client()).summary
    summary['rank_stamp'] = stamp
    done.write_text(json.dumps(summary, indent=1, default=str))
    return summary


def _inputs_key(spec: RankSpec, trial: RankTrial) -> str:
    """Return the trial's task and the mesh as a key part (their content hashes)."""
    return inputs_key(trial.primitive, trial.task or spec.replay.task, spec.cloth_mesh)


def _cell(spec: RankSpec, engine: str, params: dict, trial: RankTrial, seed: int, rate: float,
          label: str) -> tuple[str, Trial]:
    # A timing cell runs the whole motion: step times of the settle phase alone say little.
    frames = None if label == 'timing' else spec.max_frames
    every = label != 'timing' and spec.metric not in OBJECTIVES  # the faces: every metric
    model = simulated_model(engine, trial.cloth, trial.primitive, spec.cloth_size,
                            spec.cloth_mass, params)  # another version, preset, device: others
    key = (
        f'{engine}|{sorted(params.items())}|{trial.bag}|{fingerprint(Path(trial.bag))}|'
        f'{seed}|{rate:g}|{objective(spec)}|'
        f'{label}|{spec.grid}|{frames}'
        + (f'|all{SURFACE_REVISION}' if every else '')  # surface metrics of that revision
        + ('' if spec.cloth_size is None and spec.cloth_mass is None  # another cloth: other cells
           else f'|{spec.cloth_size}|{spec.cloth_mass}')
        + ('' if spec.settle == FULL else f'|settle {spec.settle}')  # full: keyed as before
        + '|' + hashlib.sha256(json.dumps(model, sort_keys=True).encode()).hexdigest()[:16]
        + '|' + _inputs_key(spec, trial)
    )
    return key, Trial(
        engine, trial.cloth, trial.primitive, trial.bag, tuple(sorted(params.items())),
        objective(spec), seed, rate, spec.grid, frames, -1, label, all_metrics=every,
        cloth_size=spec.cloth_size, cloth_mass=spec.cloth_mass, settle=spec.settle,
        task=spec.replay.task, cloth_mesh=spec.cloth_mesh,
    )


def motion_of(trial: RankTrial) -> str:
    """Return the motion a trial was recorded along: its task file's hash ('' : the task's)."""
    return trial.task_sha256


def _run_cells(client: Any, left: list[tuple[str, Trial, dict]], path: Path, done: dict,
               progress: bool) -> None:
    """
    Run the cells, each row appended as it finishes (Ctrl-C keeps them).

    Cells that differ only in their trial share one simulation (shared_simulations.pool_cells).
    The timing cells run last, one at a time: a step time is not shared with another cell. A cell
    that cannot run (status error) ends the command: exit 2 for input it refuses, and a bug in a
    worker is raised as it is (exit 1); either way it is never counted as a divergence.
    """
    bar = tqdm(total=len(left), desc='rank cells', unit='cell', disable=not progress,
               file=sys.stderr, dynamic_ncols=True)

    def keep(members: list[tuple[str, Trial, dict]], pooled: Trial, result: dict) -> None:
        for (key, cell, meta), one in zip(members, split_pooled(
                pooled, result, [c for _, c, _ in members])):
            if one['status'] == 'error':  # never a gap in the ranking, nor a divergence
                raise RankError(f'rank: {cell.engine} on {meta["trial"]} (seed {cell.seed}, '
                                f'{cell.sampler}) could not run: {one["reason"]}')
            row = {'key': key, **meta, 'engine': cell.engine, 'seed': cell.seed,
                   'rate_hz': cell.rate_hz, 'config': cell.sampler, **one}
            append_row(path, row)
            done[key] = row
        bar.update(len(members))

    scored = [c for c in left if c[2]['kind'] != 'timing']
    futures: dict[Any, tuple[Trial, list[tuple[str, Trial, dict]]]] = {}
    for pooled, indices in pool_cells([c for _, c, _ in scored]):
        futures[client.submit(evaluate, pooled, pure=False)] = (
            pooled, [scored[i] for i in indices])
    for future in as_completed(futures):
        trial, members = futures[future]
        keep(members, trial, future.result())
    for timing in (c for c in left if c[2]['kind'] == 'timing'):
        keep([timing], timing[1], client.submit(evaluate, timing[1], pure=False).result())
    bar.close()


def objective(spec: RankSpec) -> str:
    """Return what identification minimises: the ranking metric if it is cd or hd, else cd."""
    return spec.metric if spec.metric in OBJECTIVES else 'cd'


def run_rank(
    spec: RankSpec,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    say: Callable[[str], None] = print,
) -> dict[str, Any]:
    """
    Run the protocol (resumable) and return every number it produced (see module doc).

    Every identification and cell runs on one cluster (`scheduler`, or `workers` local processes),
    started when the first of them needs it.
    """
    out = check_output_dir(spec.output)
    with ResultsLock(out, 'rank'), ClusterOnDemand(scheduler, workers,
                                                   out / 'workers.log') as cluster:
        trials = prepare_trials(recordings_of(spec.recordings), spec.replay, out / 'trials', say,
                                spec.tasks)
        groups = groups_of(trials, say)
        if not groups:
            raise RankError(
                f'rank: no cloth and task with two usable trials among {len(trials)} trials '
                'found; record the task at least twice'
            )
        identified: dict[str, Any] = {}
        todo: list[tuple[str, Trial, dict]] = []
        for (cloth, primitive), members in groups.items():
            group = f'{cloth}_{primitive}'
            if spec.cloth_size is not None or spec.cloth_mass is not None:
                say(f'{group}: {len(members)} trials of a '
                    f'{cloth_name(spec.cloth_size, spec.cloth_mass)} cloth')
            for engine, overrides in spec.entrants:
                name = entrant_key(engine, overrides)
                preset = {**spec.fixed.get(engine, {}), **overrides}
                for k, held in enumerate(folds(len(members))):
                    train = [t for i, t in enumerate(members) if i not in held]
                    say(f'identify {name} on {group} fold {k + 1}: {len(train)} training trials')
                    summary = _identify(spec, engine, overrides, train, members,
                                        out / 'identify' / group / name / f'fold{k + 1}',
                                        cluster, progress, say)
                    fitted = {**preset, **summary['params']}
                    identified[f'{group}|{name}|{k + 1}'] = {
                        'group': group, 'entrant': name, 'fold': k + 1,
                        'training': [t.name for t in train], 'params': summary['params'],
                        'value': summary['value'], 'best_sampler': summary['best_sampler'],
                        'trials': {s: v['trials'] for s, v in summary['per_sampler'].items()},
                    }
                    meta = {'group': group, 'entrant': name, 'fold': k + 1,
                            'device': resolved_device(engine, preset)}
                    fitted_motions = {motion_of(t) for t in train}
                    for i in held:  # a motion the fold was not fitted on: the cross-motion check
                        other = motion_of(members[i]) not in fitted_motions
                        for seed in range(1, spec.seeds + 1):
                            for label, params in (('identified', fitted), ('preset', preset)):
                                key, cell = _cell(spec, engine, params, members[i], seed,
                                                  spec.rate_hz, label)
                                todo.append((key, cell, {**meta, 'trial': members[i].name,
                                                         'kind': 'held_out',
                                                         'other_motion': other}))
                    if k == 0:
                        for rate in spec.rates:
                            key, cell = _cell(spec, engine, fitted, members[0], 1, rate, 'timing')
                            todo.append((key, cell, {**meta, 'trial': members[0].name,
                                                     'kind': 'timing'}))
                        for (c2, p2), others in groups.items():
                            if c2 == cloth and p2 != primitive:  # the cross-task check
                                for t in others:
                                    key, cell = _cell(spec, engine, fitted, t, 1, spec.rate_hz,
                                                      f'cross:{primitive}')
                                    todo.append((key, cell, {**meta, 'trial': t.name,
                                                             'group': f'{c2}_{p2}',
                                                             'fitted_on': group,
                                                             'kind': 'cross_task'}))
        done = _read_cells(out / CELLS_FILE)
        left = [(k, c, m) for k, c, m in todo if k not in done]
        say(f'cells: {len(todo)} ({len(todo) - len(left)} kept from an earlier run)')
        if left:
            _run_cells(cluster.client(), left, out / CELLS_FILE, done, progress)
        vertices = grid_vertices(spec.grid, spec.cloth_size)
        return {
            'spec': {
                'recordings': [str(r) for r in spec.recordings],
                'entrants': [entrant_key(e, o) for e, o in spec.entrants],
                'devices': {entrant_key(e, o): resolved_device(e, {**spec.fixed.get(e, {}), **o})
                            for e, o in spec.entrants},
                'trials': spec.trials, 'sampler': spec.sampler, 'seeds': spec.seeds,
                'rate_hz': spec.rate_hz, 'rates': list(spec.rates), 'grid': spec.grid,
                'metric': spec.metric, 'objective': objective(spec),
                'max_frames': spec.max_frames, 'fidelity': spec.fidelity,
                'settle': spec.settle, **cloth_record(spec.cloth_size, spec.cloth_mass),
                **inputs_record(spec.replay.primitive,
                                [t or spec.replay.task for t in spec.tasks or ['']],
                                spec.cloth_mesh, spec.gripper_frames, spec.table_z),
            },
            'trials': [t.as_dict() for t in trials],
            'groups': {
                f'{c}_{p}': {
                    'cloth': c, 'primitive': p, 'trials': [t.name for t in m],
                    **cloth_record(spec.cloth_size, spec.cloth_mass),
                    'folds': [[m[i].name for i in held] for held in folds(len(m))],
                    'floor': floor(m, vertices),
                    'reference_error': reference_error(m),
                    'motions': len({motion_of(t) for t in m}),
                }
                for (c, p), m in groups.items()
            },
            'identified': identified,
            'cells': [replace_nan(done[k]) for k, _, _ in todo if k in done],
        }


def replace_nan(row: dict) -> dict:
    """Return the row with non-finite numbers as None (rank.json is strict JSON)."""
    def fix(v: Any) -> Any:
        if isinstance(v, float) and v != v or v in (float('inf'), float('-inf')):
            return None
        if isinstance(v, dict):
            return {k: fix(x) for k, x in v.items()}
        if isinstance(v, list):
            return [fix(x) for x in v]
        return v
    return fix(dict(row))
