"""
Cloth parameter presets per engine x cloth x task, from config/presets/<engine>.yaml.

A preset file reads
    engine: mujoco
    engine_version: "4.0.0"
    provenance: "<where the numbers come from; what was changed for this engine version>"
    presets: {towel: {dynamic: {param: value, ...}, quasi_static: {...}}, chequered: ...}
An entry stands for the engine model it names (`model: xpbd`), or for any model if it names none.
A preset set (`--presets identified`, a user's directory) may hold one entry per model instead:
    presets: {towel: {dynamic: {xpbd: {model: xpbd, ...}, vbd: {model: vbd, ...}}}}
The model that runs is decided first (a `model` override, else the shipped preset's model), then
the set gives that model's entry; a set without one is an error, never another model's values.
The shipped presets (config/presets/<engine>.yaml) are the base of every model: an override of
`model` runs that model with their physical values.
Every problem with a file (missing keys, wrong types, unknown or out-of-range parameters) is an
EngineError of one line naming the file.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
import re
from typing import Iterable

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_size import is_benchmark_cloth, with_cloth_mass
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.options import CLOTHS  # noqa: F401  (re-exported)
from cloth_bench_ros.options import PRIMITIVES
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.safe_io import atomic_write_text, load_yaml_file, UnsafeInputError
import yaml

REQUIRED_KEYS = ('engine', 'engine_version', 'provenance', 'presets')
MAX_PRESET_BYTES = 1024 * 1024


def config_dir() -> Path:
    """<repo>/config in a source checkout, else <prefix>/share/cloth_bench_ros/config."""
    return share_dir('config')


def preset_file(engine: str, config_dir_: Path | None = None) -> Path:
    """
    Return the preset file of an engine: <config>/presets/<engine>.yaml (or <dir>/<engine>.yaml).

    A directory given by the user must exist (EngineError naming it), never falling back silently.
    """
    if config_dir_ is not None:
        try:
            validation.existing_dir(config_dir_, 'presets directory')
        except validation.InputError as exc:
            raise EngineError(str(exc)) from None
    base = Path(config_dir_) if config_dir_ is not None else config_dir()
    nested = base / 'presets' / f'{engine}.yaml'
    return (
        nested
        if nested.is_file() or not (base / f'{engine}.yaml').is_file()
        else base / f'{engine}.yaml'
    )


def read_preset_file(path: Path) -> dict:
    """Return the parsed, structurally checked preset file."""
    try:
        data = load_yaml_file(path, MAX_PRESET_BYTES)
    except UnsafeInputError as exc:
        raise EngineError(f'preset file {exc}') from None
    if not isinstance(data, dict):
        raise EngineError(
            f'preset file {path}: expected a mapping with keys {", ".join(REQUIRED_KEYS)}'
        )
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise EngineError(f'preset file {path}: missing key {", ".join(missing)}')
    if data['engine'] != path.stem:
        raise EngineError(
            f'preset file {path}: engine is {data["engine"]!r}, expected {path.stem!r}'
        )
    presets = data['presets']
    if not isinstance(presets, dict):
        raise EngineError(f'preset file {path}: presets must map cloth -> primitive -> parameters')
    for cloth, tasks in presets.items():
        if cloth not in CLOTHS:
            raise EngineError(
                f'preset file {path}: unknown cloth {cloth!r} (valid: {", ".join(CLOTHS)})'
            )
        if not isinstance(tasks, dict):
            raise EngineError(
                f'preset file {path}: presets.{cloth} must map primitive -> parameters'
            )
        for primitive, values in tasks.items():
            if primitive not in PRIMITIVES:
                raise EngineError(
                    f'preset file {path}: unknown primitive {primitive!r} in presets.{cloth} '
                    f'(valid: {", ".join(PRIMITIVES)})'
                )
            model_entries(values, path, f'{cloth}.{primitive}')
    return data


def model_entries(entry: object, path: Path, where: str) -> dict[str | None, dict]:
    """
    Return an entry's parameters by the model they stand for (None: any model).

    An entry is one parameter mapping or one per model ({xpbd: {...}, vbd: {...}}); EngineError
    (one line naming the file) for anything else.
    """
    shape = f'preset file {path}: presets.{where} must map parameter -> value, or model -> ' \
            'parameters'
    if not isinstance(entry, dict) or not entry or not all(isinstance(k, str) for k in entry):
        raise EngineError(shape)
    nested = [isinstance(v, dict) for v in entry.values()]
    if not any(nested):
        model = entry.get('model')
        return {None if model is None else str(model): entry}
    if not all(nested):
        raise EngineError(f'{shape}, not both')
    for model, values in entry.items():
        if not values or not all(isinstance(k, str) for k in values):
            raise EngineError(f'preset file {path}: presets.{where}.{model} must map parameter ->'
                              ' value')
        if any(isinstance(v, dict) for v in values.values()):
            raise EngineError(shape)
        if values.get('model', model) != model:
            raise EngineError(f'preset file {path}: presets.{where}.{model} has model '
                              f'{values["model"]!r}')
    return {model: {'model': model, **values} for model, values in entry.items()}


_PRESET_FILES: dict[tuple, dict] = {}  # parsed preset files, by path, size and modification time


def _read_preset_file_cached(path: Path) -> dict:
    """Return `read_preset_file(path)`, parsed once per process while the file is unchanged."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _PRESET_FILES:
        if len(_PRESET_FILES) >= 64:
            _PRESET_FILES.clear()
        _PRESET_FILES[key] = read_preset_file(path)
    return copy.deepcopy(_PRESET_FILES[key])  # callers own what they get


def load_preset(
    engine: str,
    cloth: str,
    primitive: str,
    config_dir: Path | None = None,
    model: str | None = None,
) -> dict:
    """
    Parameters of `engine` for `cloth` and `primitive`, checked against the engine's schema.

    config_dir: a preset set's directory (None: the shipped presets). model: the model that runs
    (None: the shipped preset's); a set gives that model's entry or an EngineError saying it has
    none. An engine without a preset file (e.g. one added by another package) gets {} (its
    defaults).
    """
    if cloth not in CLOTHS:
        raise EngineError(f'unknown cloth {cloth!r} (valid: {", ".join(CLOTHS)})')
    if primitive not in PRIMITIVES:
        raise EngineError(f'unknown primitive {primitive!r} (valid: {", ".join(PRIMITIVES)})')
    path = preset_file(engine, config_dir)
    if not path.is_file():
        if config_dir is not None:  # the user named a directory: a missing file is not "defaults"
            raise EngineError(
                f'presets directory {config_dir}: no {engine}.yaml (nor presets/{engine}.yaml)'
            )
        return {}
    presets = _read_preset_file_cached(path)['presets']
    try:
        entry = presets[cloth][primitive]
    except KeyError:
        raise EngineError(f'preset file {path}: no preset for {cloth} {primitive}') from None
    where = f'{cloth}.{primitive}'
    entries = model_entries(entry, path, where)
    if config_dir is None and len(entries) == 1:
        values = dict(next(iter(entries.values())))  # the shipped preset: the base of any model
    else:
        runs = model or (
            default_model(engine, cloth, primitive) if config_dir else next(iter(entries))
        )
        values = dict(entries.get(runs) or entries.get(None) or {})
        if not values:
            raise EngineError(
                f'preset file {path}: no {engine} {runs} entry for {cloth} {primitive} (it has:'
                f' {", ".join(str(m) for m in entries)}); run one of those ({engine}.model, e.g.'
                f' --set {engine}.model={next(iter(entries))}) or {runs} with the shipped presets'
            )
        if runs is not None:  # an entry for any model runs the model decided, never the default
            values.setdefault('model', runs)
        where = f'{where}.{runs}' if runs in entries else where
    _check_against_engine(engine, values, path, where)
    return values


# How a provenance names the device a preset was fitted on (identify.output writes it).
_FITTED_ON = re.compile(r'\bon device (cpu|cuda(?::\d+)?)\b')
_ENTRY_KEY = re.compile(r'\w+ \w+(?: \(\w+\))?$')  # a merged set's "<cloth> <task> (<model>)"


def fitted_device(
    engine: str, cloth: str, primitive: str, config_dir: Path | None = None,
    model: str | None = None,
) -> str | None:
    """
    Return the device the preset an engine runs was fitted on, as its provenance says; else None.

    A merged set names it in the entry's paragraph, an identification's preset file in its one
    provenance; hand-set presets and fits made before the device was written name none.
    """
    path = preset_file(engine, config_dir)
    if not path.is_file():
        return None
    paragraphs = str(_read_preset_file_cached(path)['provenance']).split('\n')
    keyed = {p.partition(': ')[0]: p for p in paragraphs}
    text = keyed.get(f'{cloth} {primitive} ({model})') or keyed.get(f'{cloth} {primitive}')
    if text is None:
        if any(_ENTRY_KEY.match(key) for key in keyed):  # a merged set without this entry's
            return None
        text = ' '.join(paragraphs)
    found = _FITTED_ON.findall(text)
    return found[-1] if found else None


def fitted_elsewhere(engine: str, device: str, fitted: Iterable[str | None]) -> str | None:
    """Return the one line that says an engine's presets were fitted on another device, or None."""
    other = sorted({f for f in fitted if f is not None and f != device})
    if not other:
        return None
    return (f'{engine}: its preset was fitted on {", ".join(other)}, it runs on {device} here: the'
            ' device changes the numbers (docs/engines.md, "Device")')


def default_model(engine: str, cloth: str, primitive: str) -> str | None:
    """Return the model an engine runs without an override: its shipped preset's, or default."""
    model = load_preset(engine, cloth, primitive).get('model')
    if model is not None:
        return str(model)
    try:
        schema = {p.name: p for p in engine_class(engine).params}
    except EngineError:
        return None
    return str(schema['model'].default) if 'model' in schema else None


def _check_against_engine(engine: str, values: dict, path: Path, where: str) -> None:
    """Raise EngineError naming the file if the engine's schema rejects a value."""
    try:
        cls = engine_class(engine)
    except EngineError:
        return
    try:
        cls.validate_params(values)
    except EngineError as exc:
        raise EngineError(f'preset file {path}: presets.{where}: {exc}') from None


# Named preset sets (`--presets NAME`), beside a directory path: the shipped presets (default)
# and the parameters identified against each bundled synthetic reference, in config/presets/<name>.
DEFAULT_SET = 'default'
IDENTIFIED_SETS = {'identified': 'mujoco', 'identified-newton-vbd': 'newton-vbd'}


@dataclass(frozen=True)
class PresetSet:
    """A set of preset files: its name as the user gave it, and its directory (None: shipped)."""

    name: str
    directory: Path | None

    @property
    def is_default(self) -> bool:
        return self.directory is None


def preset_set(value: str | Path | None) -> PresetSet:
    """
    Return the preset set a `--presets` value names: default, identified, ... or a directory.

    EngineError (one line) for a value that is neither a set's name nor an existing directory.
    """
    text = str(value or '').strip() or DEFAULT_SET
    if text == DEFAULT_SET:
        return PresetSet(DEFAULT_SET, None)
    if text in IDENTIFIED_SETS:
        return PresetSet(text, config_dir() / 'presets' / text)
    if Path(text).is_dir():
        return PresetSet(text, Path(text))
    names = ', '.join((DEFAULT_SET, *IDENTIFIED_SETS))
    raise EngineError(f'--presets {text}: neither a preset set ({names}) nor a directory')


def identified_set_of(reference: str) -> str:
    """Return the name of the set identified against a synthetic reference (mujoco, newton-vbd)."""
    for name, ref in IDENTIFIED_SETS.items():
        if ref == reference:
            return name
    raise EngineError(f'no identified preset set for reference {reference!r}')


def merge_identified(preset_files: list[Path], out_dir: Path) -> list[Path]:
    """
    Merge identification outputs (<output>/presets/<engine>.yaml) into one file per engine.

    Each identified entry goes under its model (presets.<cloth>.<task>.<model>), with its
    provenance paragraph "<cloth> <task> (<model>): ...". A file already in out_dir is extended:
    an entry of the same cloth, task and model is replaced, every other entry stays (a Newton VBD
    identification sits beside the XPBD one). Returns the files written.
    """
    merged: dict[str, dict] = {}
    for path in preset_files:
        data = read_preset_file(path)
        engine = data['engine']
        doc = merged.get(engine)
        if doc is None:
            doc = merged[engine] = _merge_base(out_dir / f'{engine}.yaml', data)
        doc['engine_version'] = data['engine_version']
        for cloth, tasks in data['presets'].items():
            for primitive, entry in tasks.items():
                for model, values in model_entries(entry, path, f'{cloth}.{primitive}').items():
                    model = model or default_model(engine, cloth, primitive)
                    doc['presets'].setdefault(cloth, {}).setdefault(primitive, {})[model] = {
                        'model': model, **values}
                    doc['provenance'][f'{cloth} {primitive} ({model})'] = data['provenance']
    return [write_merged_set(doc, out_dir) for _, doc in sorted(merged.items())]


def write_merged_set(doc: dict, out_dir: Path) -> Path:
    """Write a merged set's file (provenance as {entry: paragraph}); return its path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    entries = [f'{cloth} {task} ({model})' for cloth, tasks in doc['presets'].items()
               for task, models in tasks.items() for model in models]
    order = {key: k for k, key in enumerate(entries)}  # paragraphs in the entries' order
    paragraphs = sorted(doc['provenance'].items(), key=lambda kv: order.get(kv[0], len(order)))
    text = {**doc, 'provenance': '\n'.join(f'{k}: {v}' for k, v in paragraphs)}
    target = out_dir / f'{doc["engine"]}.yaml'
    atomic_write_text(target, yaml.safe_dump(text, sort_keys=False, width=100))
    read_preset_file(target)  # what was written must load
    return target


def _merge_base(existing: Path, first: dict) -> dict:
    """
    Return the merge's start: an existing merged file's entries by model, keyed provenance.

    Empty without a file. A set written before entries were kept per model ("<cloth> <task>: "
    paragraphs, one entry each) is read too, each entry under the model it names.
    """
    doc = {'engine': first['engine'], 'engine_version': first['engine_version'],
           'provenance': {}, 'presets': {}}
    if not existing.is_file():
        return doc
    data = read_preset_file(existing)
    doc['engine_version'] = data['engine_version']
    keys = {}  # a provenance paragraph's key -> the entry's key "<cloth> <task> (<model>)"
    for cloth, tasks in data['presets'].items():
        for primitive, entry in tasks.items():
            entries = model_entries(entry, existing, f'{cloth}.{primitive}')
            for model, values in entries.items():
                model = model or default_model(first['engine'], cloth, primitive)
                doc['presets'].setdefault(cloth, {}).setdefault(primitive, {})[model] = {
                    'model': model, **values}
                keys[f'{cloth} {primitive} ({model})'] = f'{cloth} {primitive} ({model})'
                if len(entries) == 1:
                    keys[f'{cloth} {primitive}'] = f'{cloth} {primitive} ({model})'
    for paragraph in str(data['provenance']).split('\n'):
        key, _, text = paragraph.partition(': ')
        if key not in keys:
            raise EngineError(f'{existing}: provenance paragraph {paragraph[:40]!r}... names no '
                              'entry ("<cloth> <task> (<model>): ..." expected): not a merged set')
        doc['provenance'][keys[key]] = text
    return doc


def sized_params(
    engine: str,
    params: dict,
    size: tuple[float, float] | None,
    mass: float | None,
    area: float | None = None,
) -> dict:
    """
    Return an engine's `params` with the total mass of a cloth of `size` (core/cloth_size.py).

    A given `mass`, else the preset's mass per area times the cloth's area (a mesh's `area` if
    given); the benchmark's cloth without a mass: `params` unchanged.
    """
    if mass is None and is_benchmark_cloth(size, area):
        return dict(params)
    schema = {p.name: p for p in engine_class(engine).params}
    if 'mass' not in schema:
        raise EngineError(
            f'engine {engine} has no mass parameter: a --cloth-size or --cloth-mass needs one'
        )
    return with_cloth_mass(params, float(schema['mass'].default), size, mass, area)
