"""
The problem an identification's journal was fitted to, so that a resumed one is the same problem.

Everything a trial's value depends on except the budget and the sampler (another `--trials` or
`--sampler` resumes the journal) and the cloth's size and mass (their study has its own name in
the journal): the bags and their data (`data.bag_layout.fingerprint`), the metric, seed, rate,
grid, frames, the engine's version, the device it runs on (`auto` resolved on this machine), the
preset's values, fixed values, search space, fidelity, settle, each bag's task file and the cloth
mesh (their content hashes: studies.recording). Kept in `<output>/problem.json`, one entry per
study of the journal; `identify` refuses, in one line, to resume a journal of another problem
(ProblemChanged; `rank` identifies such a fold afresh). A key that a recorded problem lacks (kept
before that key was) is not a change, but the settle: such a problem was settled in full.

`simulated_model` is the part of it that every stored simulation depends on beyond its own
parameters (the engine's version, the preset they are set on and the device): rank's kept
simulations and cells carry it, so a project or engine update, or another machine whose `auto`
is another device, never reuses a result of the one before.
"""

from __future__ import annotations

from functools import lru_cache
import json
from pathlib import Path
from typing import Any, Mapping

from cloth_bench_ros.data.bag_layout import fingerprint
from cloth_bench_ros.engines import engine_class, engine_device
from cloth_bench_ros.engines.presets import load_preset, sized_params
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.identify.errors import ProblemChanged
from cloth_bench_ros.identify.objective import bag_task
from cloth_bench_ros.identify.spec import IdentifySpec
from cloth_bench_ros.safe_io import atomic_write_text, read_text_bounded
from cloth_bench_ros.studies.cloth import cloth_name
from cloth_bench_ros.studies.recording import file_sha256, task_record
from optuna.distributions import distribution_to_json

PROBLEM_FILE = 'problem.json'
# How a changed key is named to the user (others: the key itself).
LABELS = {'engine_version': 'engine version', 'fixed': 'fixed values', 'preset': 'preset values',
          'tasks': 'task file', 'cloth_mesh': 'cloth mesh'}


def study_key(spec: IdentifySpec) -> str:
    """Return the name of an IdentifySpec's studies in the journal, less the sampler."""
    other = spec.cloth_size is not None or spec.cloth_mass is not None  # its own study
    cloth = f'-{cloth_name(spec.cloth_size, spec.cloth_mass)}' if other else ''
    return f'{spec.engine}-{spec.cloth}-{spec.primitive}{cloth}'


def _json(value: Any) -> Any:
    """Return `value` as it reads back from JSON (tuples as lists), to compare with a file's."""
    return json.loads(json.dumps(value, sort_keys=True, default=str))


@lru_cache(maxsize=64)
def _simulated_model(engine: str, cloth: str, primitive: str, size: Any, mass: Any) -> str:
    preset = sized_params(engine, load_preset(engine, cloth, primitive), size, mass)
    return json.dumps({'engine_version': engine_class(engine).version(), 'preset': preset},
                      sort_keys=True, default=str)


@lru_cache(maxsize=64)
def _device(engine: str, device: str | None) -> str:
    return engine_device(engine, {} if device is None else {'device': device})


def resolved_device(engine: str, params: Mapping[str, Any]) -> str:
    """Return the device `engine` runs on here with `params` (`auto` resolved; `cpu` if none)."""
    device = params.get('device')
    return _device(engine, None if device is None else str(device))


def simulated_model(engine: str, cloth: str, primitive: str, cloth_size: Any = None,
                    cloth_mass: Any = None, params: Mapping[str, Any] | None = None) -> dict:
    """
    Return the engine's version, the (sized) preset a trial's parameters are set on, and device.

    The device is the one the engine runs on here with `params` (the trial's overrides).
    """
    size = tuple(cloth_size) if cloth_size is not None else None
    model = json.loads(_simulated_model(engine, cloth, primitive, size, cloth_mass))
    model['device'] = resolved_device(engine, {**model['preset'], **(params or {})})
    return model


def identify_problem(spec: IdentifySpec, space: dict, preset: dict) -> dict:
    """
    Return the problem an IdentifySpec identifies over `space` (name -> distribution), as JSON.

    `preset`: the engine's preset for the cloth (sized), on which trials set their parameters.

    Not in it: the budget, the samplers, the cloth's size and mass, and rank's `pool` and
    `shared` (they change no value).
    """
    bags = [Path(spec.bag), *(Path(b) for b in spec.also)]
    return _json({
        'engine': spec.engine,
        'cloth': spec.cloth,
        'primitive': spec.primitive,
        'bags': [{'bag': str(b.resolve()), 'fingerprint': fingerprint(b)} for b in bags],
        'objective': spec.objective,
        'seed': spec.seed,
        'rate_hz': float(spec.rate_hz),
        'grid': spec.grid,
        'max_frames': spec.max_frames,
        'engine_version': engine_class(spec.engine).version(),
        'device': resolved_device(spec.engine, {**preset, **spec.fixed}),
        'preset': dict(preset),
        'fixed': dict(spec.fixed),
        'space': {name: json.loads(distribution_to_json(d)) for name, d in space.items()},
        'fidelity': spec.fidelity,
        'settle': spec.settle,
        # the bags' tasks (each one's recorded motion, else --task, else the shipped one) and mesh
        'tasks': sorted({task_record(spec.primitive, bag_task(str(b), spec.task))['sha256']
                         for b in bags}),
        'cloth_mesh': file_sha256(spec.cloth_mesh),
    })


def changed_keys(old: dict, new: dict) -> list[str]:
    """
    Return what differs between two problems in the keys both hold: e.g. ['bag data', 'rate_hz'].

    Bags: `bags` where their paths differ, `bag data` where only their fingerprints do. Space:
    `params` where other parameters are fitted, `bounds of <name>` where a range changed.
    """
    changed = []
    for key in sorted(set(old) & set(new), key=lambda k: (k != 'bags', k)):
        a, b = old.get(key), new.get(key)
        if a == b:
            continue
        if key == 'bags' and isinstance(a, list) and isinstance(b, list):
            paths_differ = [x.get('bag') if isinstance(x, dict) else x for x in a] != [
                x.get('bag') if isinstance(x, dict) else x for x in b]
            changed.append('bags' if paths_differ else 'bag data')
        elif key == 'space' and isinstance(a, dict) and isinstance(b, dict):
            if sorted(a) != sorted(b):
                changed.append('params')
            else:
                changed.append('bounds of ' + ', '.join(n for n in sorted(a) if a[n] != b[n]))
        else:
            changed.append(LABELS.get(key, key))
    return changed


def _read_problems(path: Path) -> dict:
    """Return the study -> problem entries of `path` ({} where there is none)."""
    if not path.exists():
        return {}
    try:
        problems = json.loads(read_text_bounded(path))
    except ValueError:
        problems = None
    if not isinstance(problems, dict) or not all(isinstance(p, dict) for p in problems.values()):
        raise InputError(
            f'identify: {path} is damaged (not the JSON object identify writes); delete its '
            'folder to start afresh, or give another --output'
        )
    return problems


def check_problem(spec: IdentifySpec, problem: dict, journal: Path) -> None:
    """
    Refuse, in one line, to resume `journal` where it was fitted to another problem.

    A journal without a problem recorded for this study (made before problems were kept) resumes,
    as does one whose problem lacks a key kept since.
    """
    if not journal.exists():
        return
    old = _read_problems(spec.output / PROBLEM_FILE).get(study_key(spec))
    if old is not None:  # a problem kept before the settle was recorded settled in full
        old = {'settle': FULL, **old}
    changed = ', '.join(changed_keys(old, problem)) if old is not None else ''
    if changed:
        raise ProblemChanged(
            f'identify: {spec.output} holds an identification of another problem ({changed} '
            'changed); give another --output, or delete that folder to start afresh', changed)


def record_problem(spec: IdentifySpec, problem: dict, journal: Path) -> None:
    """Write `problem` as the study's in `<output>/problem.json` (alone, where no journal is)."""
    path = spec.output / PROBLEM_FILE
    problems = _read_problems(path) if journal.exists() else {}
    problems[study_key(spec)] = problem
    atomic_write_text(path, json.dumps(problems, indent=1, sort_keys=True) + '\n')
