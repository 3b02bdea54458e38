"""
The objective of parameter identification: one scored simulation of a trial's parameters.

A trial drives the engine directly along the primitive's targets (settle phase included) and
scores it with the evaluator's core (core.evaluation.OnlineEvaluator: the same pairing and the
same CD/HD as `cloth-bench run`), stopping after the last real frame the objective uses (the
change of phase of a dynamic trial; `max_frames` cuts it shorter). A worker decodes a bag's
clouds once and keeps them, with their k-d trees, for every later trial on that bag. With a `rung`
(multi-fidelity identification), the value over that first fraction of each bag's frames is
reported as `partial`, and the trial stops there, `pruned`, where it is above `prune_above`; with
a `ladder` of coarser meshes, the whole window is scored on each (`partials`, coarsest first), and
the trial stops, `pruned`, at the first whose value is above its threshold, else it is run whole
on its own mesh.
The evaluator core is given no mesh faces here, so a trial computes the paper's CD/HD (its
objective) and none of the metrics beside them (docs/metrics.md), which would cost it tens of
milliseconds per frame; `all_metrics` gives it the mesh's faces, and the trial returns every
metric of metric_choice (`metrics`: rank's held-out cells).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
import os
from pathlib import Path
import time
from typing import Any

from cloth_bench_ros.command_options import COMMAND_FLAGS
from cloth_bench_ros.core.cloth_mesh import mesh_area, run_cloth
from cloth_bench_ros.core.cloth_size import grasp_width
from cloth_bench_ros.core.evaluation import OnlineEvaluator
from cloth_bench_ros.core.phase import first_table_contact
from cloth_bench_ros.core.pointcloud2 import as_carried, drop_nan
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.data.bag_reader import decode_cloud
from cloth_bench_ros.data.errors import BagError
from cloth_bench_ros.engines import make_engine
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.engines.settle import FULL, Settler
from cloth_bench_ros.errors import ClothBenchError, one_line
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.metric_choice import METRICS
from cloth_bench_ros.options import OPTIONS
import numpy as np

FPS = 30.0
# A trial bag of a recorded motion carries its task file (rank.trials writes it): the
# engines follow it on that bag, and the bag's fingerprint changes with it.
TASK_IN_BAG = 'task.yaml'
_BAG_CACHE: dict[tuple, tuple] = {}
_BAG_CACHE_SIZE = 4


@dataclass(frozen=True)
class Trial:
    """One simulation of an identification: the parameters and what to score them against."""

    engine: str
    cloth: str
    primitive: str
    bag: str
    params: tuple[tuple[str, object], ...]  # sorted (name, value) on top of the preset
    objective: str = COMMAND_FLAGS['objective'].default
    seed: int = 0
    rate_hz: float = OPTIONS['rate_hz'].default
    grid: tuple[int, int] | None = None
    max_frames: int | None = None  # score at most this many frames of the window
    number: int = -1  # Optuna's trial number (-1: the preset, before identification)
    sampler: str = ''
    also: tuple[str, ...] = ()  # more bags of the task: the value is the mean over every bag
    rung: float | None = None  # multi-fidelity: score this fraction of the frames first
    prune_above: float | None = None  # stop (pruned) where that partial value is above this
    ladder: tuple[tuple[tuple[int, int], float | None], ...] = ()  # (mesh, prune above) first
    all_metrics: bool = False  # also every metric the evaluator reports (given the mesh's faces)
    cloth_size: tuple[float, float] | None = None  # (W, L) m; None: the benchmark's 0.5 x 0.7
    cloth_mass: float | None = None  # kg; None: the preset's mass per area times the area
    settle: str = FULL  # the settle phase (engines.settle): full (the paper's) or fast
    task: str = ''  # a task file for bags without their own (TASK_IN_BAG); '': the shipped one
    cloth_mesh: str = ''  # a cloth mesh file (--cloth-mesh); '': the grid


def trial_of(
    spec: IdentifySpec, params: dict, number: int, sampler: str, rung: dict | None = None
) -> Trial:
    """Return an IdentifySpec's trial of `params`; `rung`: the Pruner's rung fields, if any."""
    return Trial(
        spec.engine, spec.cloth, spec.primitive, str(spec.bag),
        tuple(sorted({**spec.fixed, **params}.items())), spec.objective, spec.seed, spec.rate_hz,
        spec.grid, spec.max_frames, number, sampler, tuple(spec.also),
        cloth_size=spec.cloth_size, cloth_mass=spec.cloth_mass, settle=spec.settle,
        task=spec.task, cloth_mesh=spec.cloth_mesh, **(rung or {}),
    )


def bag_task(bag: str, task: str = '') -> str:
    """Return the task file a bag is scored along: its own (TASK_IN_BAG), else `task`."""
    own = Path(bag) / TASK_IN_BAG
    return str(own) if own.is_file() else task


def bag_clouds(
    bag: str, keep: int = _BAG_CACHE_SIZE
) -> tuple[int | None, list[tuple[int, np.ndarray, int]]]:
    """
    Return a bag's change-of-phase frame and (stamp ns, points, NaN dropped), decoded once.

    The worker keeps the `keep` bags used last: a trial scored on more bags than the cache held
    would decode every one of them again each trial.
    """
    st = os.stat(bag) if os.path.isfile(bag) else os.stat(Path(bag) / 'metadata.yaml')
    key = (str(Path(bag).resolve()), st.st_mtime_ns, st.st_size)
    if key not in _BAG_CACHE:
        with BagReader(Path(bag)) as reader:
            topic = reader.cloud_topic()
            frames = []
            for i, (_, _, stamp, cdr) in enumerate(reader.raw_messages([topic])):
                points, dropped = drop_nan(decode_cloud(bag, topic, i, stamp, cdr)[0])
                frames.append((stamp, points, dropped))
            trial = reader.trial
        cop = trial.change_of_phase_frame if trial is not None else None
        if cop is None and (
            trial is None or trial.primitive == 'dynamic'
        ):  # found in the data, as a run does
            cop = first_table_contact(points for _, points, _ in frames).index
        while len(_BAG_CACHE) >= keep:
            _BAG_CACHE.pop(next(iter(_BAG_CACHE)))
        _BAG_CACHE[key] = (cop, frames)
    _BAG_CACHE[key] = _BAG_CACHE.pop(key)  # the least recently used goes first
    return _BAG_CACHE[key]


def evaluate(trial: Trial) -> dict:
    """
    Run one trial: status ok (value finite), diverged (reason, step) or error (refused input).

    Only the engine's own instability signals make it diverged, and only the project's
    user-facing errors make it an error; any other exception is a bug and is raised. Bags of
    different motions (their own task files) are one simulation per motion, scored together.
    """
    bags = (trial.bag, *trial.also)
    motions: dict[str, list[int]] = {}
    for i, bag in enumerate(bags):
        motions.setdefault(bag_task(bag, trial.task), []).append(i)
    if len(motions) > 1:
        return _motions(trial, list(motions.values()))
    if not trial.ladder:
        return _evaluate(trial)
    partials: list[float] = []
    cpu_s = wall_s = 0.0  # the rungs', before the trial's own run
    for grid, above in trial.ladder:
        low = _evaluate(replace(trial, grid=grid, ladder=()))
        partials.append(low['value'] if low['status'] == 'ok' else math.inf)
        if above is not None and not partials[-1] <= above:
            low.update(
                status='pruned', reason=f'partial value on the {grid[0]} x {grid[1]} mesh above '
                'the threshold', value=math.nan, CD=math.nan, HD=math.nan, frames=0, step=None,
            )
            for key in ('step_p50_ms', 'step_p99_ms'):  # the coarse mesh's, not the trial's
                low.pop(key, None)
            out = low
            break
        cpu_s, wall_s = cpu_s + low['cpu_s'], wall_s + low['wall_s']
    else:
        out = _evaluate(replace(trial, ladder=()))
    out.update(partial=partials[-1], partials=partials, cpu_s=out['cpu_s'] + cpu_s,
               wall_s=out['wall_s'] + wall_s)
    return out


def _motions(trial: Trial, groups: list[list[int]]) -> dict:
    """Return the result over bags of several motions: one evaluation per motion, per bag."""
    bags = (trial.bag, *trial.also)
    parts = [evaluate(replace(trial, bag=bags[g[0]], also=tuple(bags[i] for i in g[1:])))
             for g in groups]
    n = len(bags)
    cd, hd, frames = [math.nan] * n, [math.nan] * n, [0] * n
    for g, r in zip(groups, parts):
        one = len(g) == 1
        for j, i in enumerate(g):
            cd[i] = r['CD'] if one else r['per_bag'][j]
            hd[i] = r['HD'] if one else r['per_bag_hd'][j]
            frames[i] = r['frames'] if one else r['per_bag_frames'][j]
    first = parts[0]
    out = {**first, 'CD': float(np.mean(cd)), 'HD': float(np.mean(hd)), 'frames': sum(frames),
           'per_bag': cd, 'per_bag_hd': hd, 'per_bag_frames': frames,
           'cpu_s': sum(r['cpu_s'] for r in parts), 'wall_s': sum(r['wall_s'] for r in parts),
           'diverged': next((r.get('diverged') for r in parts if r.get('diverged')), None)}
    out['value'] = out['CD'] if trial.objective == 'cd' else out['HD']
    if all('partial' in r for r in parts):
        out['partial'] = float(np.mean([r['partial'] for r in parts]))
    if trial.all_metrics and all('metrics' in r for r in parts):
        weights = [len(g) for g in groups]
        out['metrics'] = {k: float(np.average([r['metrics'][k] for r in parts], weights=weights))
                          for k in first['metrics']}
    failed = next((r for r in parts if r['status'] != 'ok'), None)
    if failed is not None:
        out.update(status=failed['status'], reason=failed['reason'], step=failed['step'])
    if failed is not None and failed['status'] == 'pruned':
        out.update(value=math.nan, CD=math.nan, HD=math.nan)
    return out


def _evaluate(trial: Trial) -> dict:
    start, cpu_start = time.perf_counter(), time.process_time()
    out: dict[str, Any] = {
        'number': trial.number,
        'sampler': trial.sampler,
        'params': dict(trial.params),
        'value': math.nan,
        'status': 'error',
        'reason': '',
        'step': None,
        'CD': math.nan,
        'HD': math.nan,
        'frames': 0,
    }
    engine = None
    try:
        size = trial.cloth_size
        task = load_task(trial.primitive, bag_task(trial.bag, trial.task) or None)
        targets = full_targets(task, trial.rate_hz, grasp_width(size))
        offset = int(round(targets.quintic_start * 1e9))
        cloth = run_cloth(trial.grid, size, trial.cloth_mesh or None, task, trial.rate_hz)
        preset = load_preset(trial.engine, trial.cloth, trial.primitive)  # for this cloth's size:
        preset = sized_params(trial.engine, preset, size, trial.cloth_mass, mesh_area(cloth))
        params = {**preset, **dict(trial.params)}
        engine = make_engine(trial.engine, trial.rate_hz, params, cloth)
        faces = engine.faces if trial.all_metrics else None
        scored = [_scored_bag(trial, bag, offset, faces, task)
                  for bag in (trial.bag, *trial.also)]
        cores = [(core, stamps[-1]) for core, stamps in scored]
        last = max(end for _, end in cores)
        rung = _rung(trial, scored)
        settler = Settler(engine, targets, trial.settle)
        for k in range(len(targets)):
            t0 = time.perf_counter()
            if k == 0:
                vertices = engine.start(trial.seed, targets.left[0], targets.right[0])
            else:
                vertices = settler.step(k, targets.left[k], targets.right[k])
            stamp = targets.stamp_ns(k)
            d = engine.divergence
            step_s = time.perf_counter() - t0
            carried = as_carried(vertices)  # as a run carries it
            for core, _ in cores:
                if settler.stepped:  # a settle target answered without a step
                    core.add_step(
                        trial.engine, stamp, k, step_s, d is not None, d.reason if d else ''
                    )
                core.add_state(trial.engine, stamp, carried)
            if d is not None or stamp >= last:
                break
            if rung is not None and stamp >= rung[0]:
                out['partial'] = _partial(trial, scored, rung[1])
                rung = None
                if trial.prune_above is not None and not out['partial'] <= trial.prune_above:
                    out.update(status='pruned', reason='partial value above the threshold')
                    return out
        suffix = task.suffix
        per_bag = []
        for core, _ in cores:
            core.finish()
            per_bag.append(core.summary()[trial.engine])
        m = per_bag[0]
        out.update(
            CD=float(np.mean([_num(b[f'CD_{suffix}']) for b in per_bag])),
            HD=float(np.mean([_num(b[f'HD_{suffix}']) for b in per_bag])),
            frames=int(sum(b['frames_in_window'] for b in per_bag)),
            step_p50_ms=_num(m['step_time']['p50']) * 1e3,
            step_p99_ms=_num(m['step_time']['p99']) * 1e3,
        )
        if trial.all_metrics:
            out['metrics'] = {
                name: float(np.mean([metric.value(b, trial.primitive) for b in per_bag]))
                for name, metric in METRICS.items()
            }
        if trial.also:  # per bag too (identify.shared_simulations keeps them for other folds)
            out['per_bag'] = [_num(b[f'CD_{suffix}']) for b in per_bag]
            out['per_bag_hd'] = [_num(b[f'HD_{suffix}']) for b in per_bag]
            out['per_bag_frames'] = [int(b['frames_in_window']) for b in per_bag]
            out['diverged'] = [m['diverged_reason'], m['diverged_at_step']] if m['diverged'] \
                else None
        out['value'] = out['CD'] if trial.objective == 'cd' else out['HD']
        if rung is not None:  # the window ended at the rung: the partial value is the whole one
            out['partial'] = out['value']
        if m['diverged'] and not math.isfinite(out['value']):
            out.update(status='diverged', reason=m['diverged_reason'], step=m['diverged_at_step'])
        elif not math.isfinite(out['value']):
            out.update(status='error', reason='no frame could be scored')
        else:
            out['status'] = 'ok'
    except ClothBenchError as exc:  # parameters the engine refuses, a bag without frames: failed
        out.update(status='error', reason=one_line(exc, with_type=True))
    finally:  # any other exception is a bug: it ends the study (exit 1), after the close
        if engine is not None:
            engine.close()
        out['wall_s'] = time.perf_counter() - start  # a pruned trial's too
        out['cpu_s'] = time.process_time() - cpu_start  # what the trial costs on an idle core
    return out


def _rung(trial: Trial, scored: list[tuple[Any, list[int]]]) -> tuple[int, list[int]] | None:
    """Return the stamp after which the partial value is known, and frames scored per bag."""
    if not trial.rung:
        return None
    counts = [max(1, math.ceil(trial.rung * len(stamps))) for _, stamps in scored]
    return max(stamps[n - 1] for (_, stamps), n in zip(scored, counts)), counts


def _partial(trial: Trial, scored: list[tuple[Any, list[int]]], counts: list[int]) -> float:
    """Return the objective over each bag's first frames (mean over bags); nan if diverged."""
    values = []
    for (core, _), n in zip(scored, counts):
        scores = [s for s in core.scores if s.in_window][:n]
        key = 'cd' if trial.objective == 'cd' else 'hd'
        values.append(float(np.mean([getattr(s, key) for s in scores])) if scores else math.nan)
    value = float(np.mean(values))
    return value if math.isfinite(value) else math.inf


def _scored_bag(
    trial: Trial, bag: str, offset: int, faces: np.ndarray | None, task: Any
) -> tuple[Any, list[int]]:
    """Return an evaluator core fed with a bag's frames of the window, and their stamps."""
    cut, frames = bag_clouds(bag, max(_BAG_CACHE_SIZE, 1 + len(trial.also)))
    core = OnlineEvaluator([trial.engine], task, offset, cut, FPS, faces=faces)
    used = [
        f
        for f in frames
        if task.suffix != 'd' or cut is None or int(round(f[0] / 1e9 * FPS)) < cut
    ]
    used = used[: trial.max_frames] if trial.max_frames else used
    if not used:
        raise BagError(f'bag {bag}: no frame to score')
    for stamp, points, dropped in used:
        core.add_real(stamp + offset, points, dropped)
    return core, [f[0] + offset for f in used]


def _num(value: object) -> float:
    return float(value) if isinstance(value, (int, float)) and value is not None else math.nan
