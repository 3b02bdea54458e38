"""
Simulations that the folds of one ranking share (rank.study's identifications).

A trial's simulation depends on the engine, its parameters, the seed, the rate, the mesh and the
cloth, never on the recording it is scored against: every trial of a cloth and task is driven
along the same targets. So a fold's identification runs each simulation once, scored on every
trial of the group (held-out ones too, written down but never part of its objective), and keeps
the per-trial values in one file. Another fold that asks for the same parameters, as a seeded
sampler does as long as the folds' values order the trials alike, takes its objective (the mean
over its own training trials) from that file instead of simulating again: the same numbers, no
engine time. Trials with a rung or a coarse ladder (multi-fidelity) are not shared.

The scoring cells of a ranking do the same within one run (pool_cells, split_pooled): cells that
differ only in the trial they score (a preset's seed on every held-out trial, one fold's
parameters on its several held-out trials) run one simulation scored on each of their trials.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
import json
import math
from pathlib import Path
from typing import Any, Sequence

from cloth_bench_ros.data.bag_layout import fingerprint
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.identify.objective import Trial
from cloth_bench_ros.identify.problem import simulated_model
from cloth_bench_ros.studies.recording import inputs_key
from cloth_bench_ros.studies.results import append_row
import numpy as np

# what every key names as the objective: a simulation does not depend on it (rows keep it)
KEY_OBJECTIVE = 'cd'


@dataclass
class KnownResult:
    """A finished result that stands where a Dask future would (result() and release())."""

    value: dict

    def result(self) -> dict:
        return self.value

    def release(self) -> None:
        pass


class SharedSimulations:
    """The group's simulations, each scored on every trial of `pool`, kept in `path` (JSONL)."""

    def __init__(self, path: Path, pool: Sequence[str]) -> None:
        self.path, self.pool = Path(path), tuple(pool)
        # A row's per-trial values name each bag with its fingerprint: a trial written again
        # with other data (its recording changed), or one the row never saw, is simulated again.
        self.names = {bag: bag_identity(bag) for bag in self.pool}
        self.rows: dict[str, dict] = {}
        self.reused = self.simulated = 0
        if self.path.exists():
            for line in self.path.read_text().splitlines():
                try:
                    row = json.loads(line)
                    self.rows[row['key']] = row
                except (ValueError, KeyError, TypeError):
                    continue  # a torn last line: that simulation runs again

    def applies(self, trial: Trial) -> bool:
        """Whether the trial's simulation can be shared: whole, and scored on bags of the pool."""
        bags = (trial.bag, *trial.also)
        return (trial.rung is None and not trial.ladder and not trial.all_metrics
                and all(b in self.pool for b in bags))

    def submit(self, client: Any, evaluate: Any, trial: Trial) -> Any:
        """Return the trial's result: known already, else the pool's simulation submitted."""
        if not self.applies(trial):
            return client.submit(evaluate, trial, pure=False)
        known = self.known(trial)
        if known is not None:
            self.reused += 1
            return KnownResult(known)
        pooled = replace(trial, bag=self.pool[0], also=self.pool[1:])
        return client.submit(evaluate, pooled, pure=False)

    def known(self, trial: Trial) -> dict | None:
        """Return the trial's result where a kept simulation has values for all its bags."""
        row = self.rows.get(_key(trial))
        if row is None or not all(self.names[b] in row['bags'] for b in (trial.bag, *trial.also)):
            return None
        return fold_result(trial, row, reused=True, names=self.names)

    def finish(self, trial: Trial, result: dict) -> dict:
        """Return the trial's own result from the pool's; keep the pool's per-trial values."""
        if not self.applies(trial) or result.get('reused'):
            return result
        self.simulated += 1
        if 'per_bag' not in result:  # it could not even run: nothing per trial to keep
            return result
        key = _key(trial)
        row: dict[str, Any] = {
            'key': key,
            'bags': {
                self.names[bag]: [cd, hd, frames] for bag, cd, hd, frames in zip(
                    self.pool, result['per_bag'], result['per_bag_hd'], result['per_bag_frames'])
            },
            **{k: result.get(k) for k in ('diverged', 'step_p50_ms', 'step_p99_ms', 'cpu_s',
                                          'wall_s')},
        }
        self.rows[key] = row

        append_row(self.path, row)
        return fold_result(trial, row, reused=False, names=self.names)


def pool_cells(trials: Sequence[Trial]) -> list[tuple[Trial, list[int]]]:
    """
    Return one trial per simulation with the indices of the trials that run it.

    Trials that differ only in their bag (and labels) share it: it is scored on each one's bag.
    """
    groups: dict[str, list[int]] = {}
    for i, trial in enumerate(trials):
        shareable = trial.rung is None and not trial.ladder and not trial.all_metrics
        groups.setdefault(_key(trial) if shareable else f'alone {i}', []).append(i)
    pooled = []
    for members in groups.values():
        bags = list(dict.fromkeys(trials[i].bag for i in members))
        pooled.append((replace(trials[members[0]], bag=bags[0], also=tuple(bags[1:])), members))
    return pooled


def split_pooled(pooled: Trial, result: dict, trials: Sequence[Trial]) -> list[dict]:
    """Return each trial's result from its pooled simulation's (the first one pays its time)."""
    if not pooled.also or 'per_bag' not in result:  # alone, or it could not even run
        return [{**result, 'number': t.number, 'sampler': t.sampler,
                 'pooled': 1 + len(pooled.also)} for t in trials]
    bags = {bag: [cd, hd, frames] for bag, cd, hd, frames in zip(
        (pooled.bag, *pooled.also), result['per_bag'], result['per_bag_hd'],
        result['per_bag_frames'])}
    row = {'bags': bags, **{k: result.get(k) for k in ('diverged', 'step_p50_ms', 'step_p99_ms',
                                                       'cpu_s', 'wall_s')}}
    names = {bag: bag for bag in bags}
    out = [fold_result(t, row, reused=i > 0, names=names) for i, t in enumerate(trials)]
    for one in out:
        one.pop('reused')
        one['pooled'] = len(names)  # trials scored on this one simulation
    return out


def bag_identity(bag: str) -> str:
    """Return a bag's path with its fingerprint (data.bag_layout: its files' names and data)."""
    return f'{bag}|{fingerprint(Path(bag))}'


def fold_result(trial: Trial, row: dict, reused: bool, names: dict[str, str]) -> dict:
    """Return what evaluate() gives for the trial's own bags, from a pooled simulation's row."""
    per = [row['bags'][names[b]] for b in (trial.bag, *trial.also)]
    cd = float(np.mean([p[0] if p[0] is not None else math.nan for p in per]))
    hd = float(np.mean([p[1] if p[1] is not None else math.nan for p in per]))
    value = cd if trial.objective == 'cd' else hd
    out = {
        'number': trial.number, 'sampler': trial.sampler, 'params': dict(trial.params),
        'value': value, 'CD': cd, 'HD': hd, 'frames': int(sum(p[2] for p in per)),
        'status': 'ok', 'reason': '', 'step': None,
        'step_p50_ms': row.get('step_p50_ms'), 'step_p99_ms': row.get('step_p99_ms'),
        'per_bag': [p[0] for p in per], 'reused': reused,
        # a reused simulation costs no engine time; the first fold's pays for it
        'cpu_s': 0.0 if reused else row.get('cpu_s'),
        'wall_s': 0.0 if reused else row.get('wall_s'),
    }
    if trial.also == ():
        out.pop('per_bag')
    diverged = row.get('diverged')
    if not math.isfinite(value):
        if diverged:
            out.update(status='diverged', reason=diverged[0], step=diverged[1])
        else:
            out.update(status='error', reason='no frame could be scored')
    return out


def _key(trial: Trial) -> str:
    """
    Return what a simulation depends on, as the key of its row.

    Every field but the bags and the trial's labels, and the engine's version, preset and device
    (another project or engine version, or another device, simulates again).
    """
    fields = asdict(replace(trial, bag='', also=(), number=-1, sampler='',
                            objective=KEY_OBJECTIVE))
    if fields['settle'] == FULL:  # as rows were keyed before the fast settle existed
        del fields['settle']
    fields['inputs'] = inputs_key(trial.primitive, trial.task, trial.cloth_mesh)
    fields['model'] = simulated_model(trial.engine, trial.cloth, trial.primitive,
                                      trial.cloth_size, trial.cloth_mass, dict(trial.params))
    return json.dumps(fields, sort_keys=True, default=str)
