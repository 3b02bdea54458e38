"""
Cloth parameter presets per engine x cloth x task, from config/presets/<engine>.yaml.

A preset file reads
    engine: mujoco
    engine_version: "4.0.0"
    provenance: "<where the numbers come from; what was changed for this engine version>"
    presets: {towel: {dynamic: {param: value, ...}, quasi_static: {...}}, chequered: ...}
Every problem with a file (missing keys, wrong types, unknown or out-of-range parameters) is an
EngineError of one line naming the file.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

from cloth_bench_ros import validation
from cloth_bench_ros.core.trajectory import PRIMITIVES
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.options import CLOTHS  # noqa: F401  (re-exported)
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.safe_io import load_yaml_file, UnsafeInputError

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
            if not isinstance(values, dict) or not all(isinstance(k, str) for k in values):
                raise EngineError(
                    f'preset file {path}: presets.{cloth}.{primitive} must map parameter -> value'
                )
    return data


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


def load_preset(engine: str, cloth: str, primitive: str, config_dir: Path | None = None) -> dict:
    """
    Parameters of `engine` for `cloth` and `primitive`, checked against the engine's schema.

    An engine without a preset file (e.g. one added by another package) gets {} (its defaults).
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
        values = dict(presets[cloth][primitive])
    except KeyError:
        raise EngineError(f'preset file {path}: no preset for {cloth} {primitive}') from None
    _check_against_engine(engine, values, path, f'{cloth}.{primitive}')
    return values


def _check_against_engine(engine: str, values: dict, path: Path, where: str) -> None:
    """Raise EngineError naming the file if the engine's schema rejects a value."""
    from cloth_bench_ros.engines import engine_class  # late: the registry imports engines

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

    A file already in out_dir is extended: each cloth and task given replaces its entry and its
    provenance paragraph, every other entry stays. Returns the files written.
    """
    from cloth_bench_ros.safe_io import atomic_write_text
    import yaml

    merged: dict[str, dict] = {}
    for path in preset_files:
        data = read_preset_file(path)
        doc = merged.get(data['engine'])
        if doc is None:
            doc = merged[data['engine']] = _merge_base(out_dir / f'{data["engine"]}.yaml', data)
        doc['engine_version'] = data['engine_version']
        for cloth, tasks in data['presets'].items():
            for primitive, values in tasks.items():
                doc['presets'].setdefault(cloth, {})[primitive] = values
                doc['provenance'][f'{cloth} {primitive}'] = data['provenance']
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for engine, doc in sorted(merged.items()):
        doc['provenance'] = '\n'.join(f'{k}: {v}' for k, v in doc['provenance'].items())
        target = out_dir / f'{engine}.yaml'
        atomic_write_text(target, yaml.safe_dump(doc, sort_keys=False, width=100))
        read_preset_file(target)  # what was written must load
        written.append(target)
    return written


def _merge_base(existing: Path, first: dict) -> dict:
    """Return the merge's start: an existing merged file's entries, keyed provenance, or empty."""
    doc = {'engine': first['engine'], 'engine_version': first['engine_version'],
           'provenance': {}, 'presets': {}}
    if not existing.is_file():
        return doc
    data = read_preset_file(existing)
    doc['presets'] = copy.deepcopy(data['presets'])
    entries = {f'{c} {p}' for c, tasks in data['presets'].items() for p in tasks}
    for paragraph in str(data['provenance']).split('\n'):
        key, _, text = paragraph.partition(': ')
        if key not in entries:
            raise EngineError(f'{existing}: provenance paragraph {paragraph[:40]!r}... names no '
                              'entry ("<cloth> <task>: ..." expected): not a merged set')
        doc['provenance'][key] = text
    return doc


def sized_params(
    engine: str, params: dict, size: tuple[float, float] | None, mass: float | None
) -> dict:
    """
    Return an engine's `params` with the total mass of a cloth of `size` (core/cloth_size.py).

    A given `mass`, else the preset's mass per area times the cloth's area; the benchmark's
    cloth without a mass: `params` unchanged.
    """
    from cloth_bench_ros.core.cloth_size import is_benchmark, with_cloth_mass
    from cloth_bench_ros.engines import engine_class

    if mass is None and is_benchmark(size):
        return dict(params)
    schema = {p.name: p for p in engine_class(engine).params}
    if 'mass' not in schema:
        raise EngineError(
            f'engine {engine} has no mass parameter: a --cloth-size or --cloth-mass needs one'
        )
    return with_cloth_mass(params, float(schema['mass'].default), size, mass)
