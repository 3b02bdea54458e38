"""
Parameter identification (`cloth-bench identify`): CMA-ES and Bayesian optimisation.

The paper's samplers, with Optuna.

The study minimises the chosen metric (CD or HD of the task's window) of an engine against a bag
over a set of the engine's parameters, with the seed held constant. Samplers: CMA-ES
(`CmaEsSampler`, started at the preset), Bayesian optimisation with TPE (`TPESampler`, the
default BO: no extra dependency) or with a Gaussian process (`GPSampler`, only where PyTorch is
installed); `both` runs CMA-ES and BO and keeps the better, as the paper did. Optuna's study stays
with the client (ask and tell, a batch of trials in flight on the Dask workers); every trial is
kept in an Optuna journal file beside the results, so an interrupted identification resumes.
A diverged trial is a failed trial with its reason and step; so is a trial the engine refuses
(status error: a project error, such as parameters the engine's compiler rejects). Any other
exception in a trial is a bug and ends the study (exit 1). The result is a preset file in the
config/presets format (`cloth-bench run --presets DIR`) with its provenance, validated on other
seeds (and the other trials' bags) against the engine's preset through the full node graph.
"""

from __future__ import annotations

from collections import deque
from contextlib import nullcontext
from dataclasses import dataclass, replace
from functools import partial
import json
import math
from pathlib import Path
import sys
import time
from typing import Any, Sequence
import warnings

from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.identify.curve import (
    AUTO_FIRST,
    AUTO_MAX_TRIALS,
    AUTO_TOLERANCE,
    best_value,
    budget_reached,
    convergence,
    finite_or_inf,
)
from cloth_bench_ros.identify.fidelity import check_fidelity, Pruner
from cloth_bench_ros.identify.objective import evaluate, Trial, trial_of
from cloth_bench_ros.identify.output import summarise, validate, write_outputs
from cloth_bench_ros.identify.problem import (
    check_problem,
    identify_problem,
    record_problem,
    study_key,
)
from cloth_bench_ros.identify.shared_simulations import SharedSimulations
from cloth_bench_ros.identify.spec import AUTO, IdentifySpec
from cloth_bench_ros.options import SAMPLERS
from cloth_bench_ros.safe_io import check_output_dir
from cloth_bench_ros.studies.dask_executor import open_client, worker_slots
from cloth_bench_ros.studies.results import append_row, ResultsLock
from distributed import KilledWorker
import optuna
from optuna.distributions import FloatDistribution
from optuna.storages import JournalStorage
from optuna.trial import TrialState
from tqdm import tqdm

try:
    from optuna.storages.journal import JournalFileBackend as JournalBackend
except ImportError:  # optuna < 4
    from optuna.storages import JournalFileStorage as JournalBackend

JOURNAL_FILE = 'study.journal'
TRIALS_FILE = 'trials.jsonl'
SUMMARY_FILE = 'identification.json'
# What the reference identified per engine (docs/benchmark.md, section 7); others: every ranged
# number.
DEFAULT_PARAMS = {
    'mujoco': ('mass', 'young', 'poisson', 'thickness', 'damping'),
    'bullet': ('mass', 'elastic', 'damping', 'bending'),
    # Newton per model: mass, membrane (springs or triangles), its damping, bending, friction.
    'newton:xpbd': ('mass', 'spring_stiffness', 'spring_damping', 'bending', 'friction'),
    'newton:vbd': ('mass', 'tri_stiffness', 'tri_damping', 'bending', 'friction'),
}
NOT_FITTED = ('timestep', 'substeps', 'solver_iterations')


def default_params(engine: str, model: str | None = None) -> list[str]:
    """Return the parameters fitted by default: the reference's set, else every ranged number."""
    schema = engine_class(engine).params
    for key in (f'{engine}:{model}', engine):
        if key in DEFAULT_PARAMS:
            return list(DEFAULT_PARAMS[key])
    return [
        p.name
        for p in schema
        if p.low is not None
        and p.high is not None
        and not p.choices
        and not isinstance(p.default, bool)
        and p.name not in NOT_FITTED
    ]


def search_space(engine: str, names: Sequence[str], base: dict, span: float) -> dict[str, Any]:
    """
    Return name -> Optuna distribution: the schema's range, or a log range around the preset.

    Where a range spans decades (high >= 100 low, or 100 times the base value when low is 0), a log
    range within a factor `span` either side of the base (preset) value. ValueError for a parameter
    that cannot be fitted.
    """
    schema = {p.name: p for p in engine_class(engine).params}
    space = {}
    for name in names:
        p = schema.get(name)
        if p is None:
            raise InputError(
                f'--param: unknown {engine} parameter {name} (known: {", ".join(schema)})'
            )
        if p.choices or isinstance(p.default, bool) or p.low is None or p.high is None:
            raise InputError(f'--param: {engine} parameter {name} is not a number with a range')
        value = float(base.get(name, p.default))
        low, high = float(p.low), float(p.high)
        decades = high >= 100 * low if low > 0 else value > 0 and high >= 100 * value
        if decades and value > 0:
            space[name] = FloatDistribution(
                max(low, value / span), min(high, value * span), log=True
            )
        else:
            space[name] = FloatDistribution(low, high)
    return space


def make_sampler(name: str, seed: int) -> Any:
    """
    Return the Optuna sampler `name` (cmaes, tpe or gp), seeded.

    CMA-ES starts at the centre of the space, which is the preset for the log-scale parameters
    (their ranges are a factor `span` either side).
    """
    if name == 'cmaes':
        return optuna.samplers.CmaEsSampler(seed=seed, warn_independent_sampling=False)
    if name == 'tpe':
        return optuna.samplers.TPESampler(seed=seed, multivariate=True, n_startup_trials=10)
    if name == 'gp':
        try:
            import torch  # noqa: F401 # lazy: optional, only --sampler gp needs PyTorch
        except ImportError:
            raise InputError(
                '--sampler gp needs PyTorch (pip install torch); use tpe or cmaes'
            ) from None
        return optuna.samplers.GPSampler(seed=seed)
    raise InputError(f'unknown sampler {name!r} (valid: {", ".join(SAMPLERS)})')


def samplers_of(choice: str) -> list[str]:
    """Return the samplers a --sampler choice runs (both: CMA-ES, then BO with TPE)."""
    if choice not in SAMPLERS:
        raise InputError(f'unknown sampler {choice!r} (valid: {", ".join(SAMPLERS)})')
    return ['cmaes', 'tpe'] if choice == 'both' else [choice]


def repair_journal(path: Path) -> int:
    """
    Drop a torn last line (a crash mid-write) from an Optuna journal, with a warning.

    Returns the bytes dropped.

    Every complete operation is kept. A bad line followed by good ones is damage, not a torn tail:
    ValueError naming the file and line.
    """
    if not path.exists():
        return 0
    data = path.read_bytes()
    lines = data.split(b'\n')
    kept = []
    for number, line in enumerate(lines, 1):
        if line.strip():
            try:
                json.loads(line)
            except ValueError:
                if any(rest.strip() for rest in lines[number:]):
                    raise InputError(
                        f'identify: journal {path} is damaged at line {number} (not a torn last '
                        'line); move it aside to start the identification again'
                    ) from None
                break
        kept.append(line)
    repaired = b'\n'.join(line for line in kept if line.strip())
    repaired += b'\n' if repaired else b''
    dropped = len(data) - len(repaired)
    if repaired != data:
        path.write_bytes(repaired)  # before Optuna appends to it
    if dropped > 0:
        warnings.warn(
            f'journal {path} ended in a torn line ({dropped} bytes, a crash while writing?); '
            'dropped it and kept every complete trial',
            stacklevel=2,
        )
    return dropped


def study_name(spec: IdentifySpec, sampler: str) -> str:
    """Return the sampler's study name: a cloth of another size or mass has its own study."""
    stem, cloth = f'{spec.engine}-{spec.cloth}-{spec.primitive}', study_key(spec)
    return f'{stem}-{sampler}{cloth[len(stem):]}'


def open_study(spec: IdentifySpec, sampler: str) -> Any:
    """
    Return the sampler's study in the journal beside the results (created, or loaded).

    Trials left running by an interrupted identification are marked failed.
    """
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings('ignore', category=optuna.exceptions.ExperimentalWarning)
    repair_journal(spec.output / JOURNAL_FILE)
    storage = JournalStorage(JournalBackend(str(spec.output / JOURNAL_FILE)))
    study = optuna.create_study(
        study_name=study_name(spec, sampler),
        storage=storage,
        sampler=make_sampler(sampler, spec.seed),
        direction='minimize',
        load_if_exists=True,
    )
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        study.tell(t.number, state=TrialState.FAIL)
    return study


def submit(client: Any, task: Trial, shared: SharedSimulations | None = None) -> Any:
    """Return the trial's future on the workers, or its result where `shared` already has it."""
    return shared.submit(client, evaluate, task) if shared else client.submit(
        evaluate, task, pure=False)


def run_sampler(
    client: Any, spec: IdentifySpec, sampler: str, space: dict, record: Any, progress: bool,
    shared: SharedSimulations | None = None,
) -> Any:
    """
    Ask and tell until the study holds `spec.trials` finished trials, a batch in flight.

    Told in trial-number order, trial n + batch asked once trial n is told: the same history
    whatever order the workers finish in, so the same trials and automatic budget every time.
    `shared` (a SharedSimulations): a simulation another fold ran already is not run again.
    """
    study = open_study(spec, sampler)
    done = (TrialState.COMPLETE, TrialState.FAIL, TrialState.PRUNED)
    finished = len(study.get_trials(deepcopy=False, states=done))
    pruner = Pruner(spec.fidelity, study, spec.grid, spec.cloth_size, spec.engine)
    left = max(0, spec.trials - finished)
    batch = spec.batch or worker_slots(client)
    bar = tqdm(
        total=spec.trials, initial=spec.trials - left, desc=f'identify {sampler}', unit='trial',
        disable=not progress, file=sys.stderr, dynamic_ncols=True,
    )
    running: deque = deque()  # (trial, future), in the order asked

    def ask() -> None:
        nonlocal left
        trial = study.ask(space)
        task = trial_of(spec, trial.params, trial.number, sampler, pruner.rung())
        running.append((trial, task, submit(client, task, shared)))
        left -= 1

    for _ in range(min(batch, left)):
        ask()
    while running:
        trial, task, future = running.popleft()
        try:
            result = future.result()
            result = shared.finish(task, result) if shared else result
        except KilledWorker as exc:  # the trial killed every worker that tried it (a bug raises)
            result = {
                'number': trial.number, 'sampler': sampler, 'params': trial.params,
                'value': math.nan, 'status': 'error', 'reason': f'{type(exc).__name__}: {exc}',
                'step': None,
            }
        future.release()
        if not pruner.tell(study, trial, result):
            trial.set_user_attr('status', result['status'])
            trial.set_user_attr('reason', str(result['reason'])[:500])
            trial.set_user_attr('step', result['step'])
            study.tell(trial, state=TrialState.FAIL)
        record(result)
        bar.set_postfix(best=f'{best_value(study):.5f}', refresh=False)
        bar.update(1)
        if left > 0:
            ask()
    bar.close()
    return study


def run_budgeted(
    client: Any, spec: IdentifySpec, sampler: str, space: dict, record: Any, progress: bool,
    shared: SharedSimulations | None = None,
) -> tuple[Any, dict]:
    """Run a sampler to spec.trials, or (AUTO) doubling from AUTO_FIRST until budget_reached."""
    run = partial(run_sampler, client, sampler=sampler, space=space, record=record,
                  progress=progress, shared=shared)
    if spec.trials != AUTO:
        return run(spec=spec), {'rule': 'fixed'}
    n, steps = AUTO_FIRST, []
    while True:
        study = run(spec=replace(spec, trials=n))
        if n == AUTO_FIRST:
            n *= 2
            continue
        enough, gain = budget_reached(convergence(study), n)
        steps.append([n // 2, n, gain])
        if enough or n >= AUTO_MAX_TRIALS:
            break
        n *= 2
    return study, {
        'rule': f'double from {AUTO_FIRST} until a doubling improves the best by less than '
        f'{AUTO_TOLERANCE:.0%} (at most {AUTO_MAX_TRIALS})',
        'doublings': steps,
        'trials': n,
        'reached': bool(enough),
    }


def record_trial(path: Path, device: str, result: dict) -> None:
    """Append a trial's result to trials.jsonl with the device it ran on."""
    append_row(path, {**result, 'device': device})


@dataclass
class IdentifyOutcome:
    summary: dict
    preset_file: Path
    wall_s: float


def identify(
    spec: IdentifySpec,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    client: Any = None,
) -> IdentifyOutcome:
    """
    Run the identification of `spec` and its validation; write the preset and its JSON.

    On `client` where one is given (rank's one cluster for all its folds), else on a cluster of its
    own (`scheduler`, or a local one of `workers` processes).
    """
    start = time.perf_counter()
    spec.output = check_output_dir(spec.output)
    shipped = load_preset(spec.engine, spec.cloth, spec.primitive)  # for the cloth's size, mass:
    sized = sized_params(spec.engine, shipped, spec.cloth_size, spec.cloth_mass)
    base = {**sized, **spec.fixed}
    names = list(spec.params) or [  # a given mass is the cloth's: not fitted
        n for n in default_params(spec.engine, base.get('model')) if n != 'mass'
        or spec.cloth_mass is None]
    space = search_space(spec.engine, names, base, spec.span)
    samplers = samplers_of(spec.sampler)
    for s in samplers:
        make_sampler(s, spec.seed)  # a missing dependency fails before any work
    check_fidelity(spec.fidelity, spec.grid, spec.cloth_size, spec.engine)
    problem = identify_problem(spec, space, sized)  # a journal resumes only the problem it fit
    check_problem(spec, problem, spec.output / JOURNAL_FILE)
    with (
        ResultsLock(spec.output, 'identify'),
        nullcontext(client) if client is not None
        else open_client(scheduler, workers, spec.output / 'workers.log') as client,
    ):
        record_problem(spec, problem, spec.output / JOURNAL_FILE)
        shared = SharedSimulations(spec.shared, spec.pool) if spec.shared else None
        preset_trial = trial_of(spec, {}, -1, 'preset')
        before = submit(client, preset_trial, shared).result()
        before = shared.finish(preset_trial, before) if shared else before
        record = partial(record_trial, spec.output / TRIALS_FILE, problem['device'])
        budgets = {s: run_budgeted(client, spec, s, space, record, progress, shared)
                   for s in samplers}
        studies = {s: study for s, (study, _) in budgets.items()}
        best = min(studies, key=lambda s: finite_or_inf(best_value(studies[s])))
        if not math.isfinite(best_value(studies[best])):
            failed = [t.user_attrs.get('status') for st in studies.values()
                      for t in st.get_trials(deepcopy=False)]
            raise InputError(
                f'identify: no trial of {", ".join(samplers)} finished: '
                f'{failed.count("diverged")} diverged, {failed.count("error")} refused by the '
                f'engine (see {spec.output / TRIALS_FILE})'
            )
        validation = validate(client, spec, {**spec.fixed, **studies[best].best_params}, progress)
        summary = summarise(spec, space, base, before, studies, best, validation)
        for s, (_, budget) in budgets.items():
            summary['per_sampler'][s]['budget'] = budget
        if shared:
            summary['shared_simulations'] = {'reused': shared.reused, 'run': shared.simulated}
        summary['wall_s'] = time.perf_counter() - start
        preset = write_outputs(spec, base, summary)
    return IdentifyOutcome(summary, preset, summary['wall_s'])
