"""
The cells of a study: one run each (engine, rate, cloth, task, bag, seed, configuration).

Two kinds of sweep build cells:

- paper (`cloth-bench sweep`): engines x rates x cloths x tasks x trials x seeds with the
  engines' presets, the layout of the paper's Table III and Fig. 5;
- settings (`cloth-bench sweep --mode settings`): per engine, a factorial sweep over the settings
  that cost time (mesh resolution, self-collision, internal time step, solver iterations) at one
  rate, to find the cheapest configuration within a tolerance of the most accurate one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from itertools import product
from pathlib import Path
import re
from typing import Iterable, Sequence

from cloth_bench_ros.core import surface_metrics
from cloth_bench_ros.data import BagReader
from cloth_bench_ros.engines import engine_class, engine_device, engine_model
from cloth_bench_ros.engines.presets import load_preset, PresetSet
from cloth_bench_ros.engines.settle import FULL
from cloth_bench_ros.errors import ClothBenchError, InputError
from cloth_bench_ros.options import FLAGS, OPTIONS, PRIMITIVES
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.studies.cloth import study_inputs
from cloth_bench_ros.studies.results import KEY_FIELDS, result_key

DEFAULT_RATES = FLAGS['rates'].default
DEFAULT_ENGINES = ('mujoco', 'bullet', 'newton')
DEFAULT_CLOTHS = ('towel', 'chequered', 'linen')
DEFAULT_PRIMITIVES = PRIMITIVES
DEFAULT_SEEDS = 20
PRESET = 'preset'

# Settings sweep (mode "settings"): the settings that cost time, each axis a list of values;
# None means "the preset's value". The cells are the full factorial product.
DEFAULT_SETTINGS_AXES: dict[str, list] = {
    'grid': [(6, 8), (11, 15), (16, 22)],
    'self_collision': [False, True],
    'timestep': [None, 0.005, 0.01],
    'solver_iterations': [None, 5],
}
SETTINGS_RATE = OPTIONS['rate_hz'].default
SETTINGS_SEEDS = 2


CROSS_REFERENCE = 'cross_reference'  # the mode of cells scored against a named synthetic reference


@dataclass(frozen=True)
class Cell:
    """One pipeline run of a sweep."""

    engine: str
    rate_hz: float
    cloth: str
    primitive: str
    seed: int
    bag: str
    trial: int = 0
    mode: str = FLAGS['sweep_mode'].default
    config: str = PRESET  # name of the engine configuration (grid + overrides)
    grid: tuple[int, int] | None = None
    overrides: tuple[tuple[str, object], ...] = ()  # sorted (parameter, value) pairs
    pacing: str = OPTIONS['pacing'].default
    keep_frames: bool = False  # write summary.json + frames.csv of this run (per-frame plots)
    cloth_size: tuple[float, float] | None = None  # (W, L) m; None: the benchmark's 0.5 x 0.7
    cloth_mass: float | None = None  # kg; None: the preset's mass per area times the area
    all_metrics: bool = False  # every metric (realtime cells: the node graph's always), or CD/HD
    settle: str = FULL  # the settle phase (engines/settle.py): full (the paper's) or fast
    task_file: str = ''  # --task: a task file instead of the shipped task of `primitive`
    task_sha256: str = ''  # of the task file's content ('': the shipped task)
    cloth_mesh: str = ''  # --cloth-mesh: the cloth as a mesh file instead of the grid
    mesh_sha256: str = ''  # of the mesh file's content

    def key(self) -> tuple:
        """Return what makes a cell unique in a results file (resume compares it with row_key)."""
        return result_key({name: getattr(self, name) for name in KEY_FIELDS})

    def ident(self) -> str:
        """Return a file-system-safe name of the cell."""
        text = (
            f'{self.mode}_{self.config}_{self.engine}_{self.rate_hz:g}hz_{self.cloth}'
            f'_{self.primitive}'
            f'_t{self.trial}_s{self.seed}_{self.pacing}'
            + ('' if self.settle == FULL else f'_settle-{self.settle}')
            + (f'_task{self.task_sha256[:8]}' if self.task_sha256 else '')
            + (f'_mesh{self.mesh_sha256[:8]}' if self.mesh_sha256 else '')
        )
        return re.sub(r'[^A-Za-z0-9_.=-]+', '-', text)

    @property
    def params(self) -> dict:
        """Return the parameter overrides on top of the preset."""
        return dict(self.overrides)

    @property
    def device(self) -> str:
        """Return the device the cell's engine runs on (Newton: its `device` or Warp's default)."""
        try:
            return engine_device(self.engine, self.params)
        except ClothBenchError:  # an engine or device not on this machine: as the cell names it
            return str(self.params.get('device', 'cpu'))

    @property
    def engine_version(self) -> str:
        """Return the version of the cell's engine on this machine ('' where it is not here)."""
        return _engine_version(self.engine)

    @property
    def surface_revision(self) -> int:
        """Return the surface metrics' revision the cell is scored with (0: it is not)."""
        return surface_metrics.SURFACE_REVISION if self.all_metrics else 0  # read when keyed

    @property
    def model(self) -> str:
        """Return the model the cell's engine runs (its overrides' on its shipped preset's)."""
        try:
            preset = load_preset(self.engine, self.cloth, self.primitive)
            return engine_model(self.engine, {**preset, **self.params})
        except ClothBenchError:  # an engine not on this machine: as the cell names it
            return str(self.params.get('model', ''))

    @property
    def reference(self) -> str | None:
        """Return the synthetic reference a cross-reference cell is scored against."""
        if self.mode != CROSS_REFERENCE:
            return None
        return self.config.split(',')[0].removeprefix('reference=')

    @property
    def preset_set(self) -> str:
        """Return the name of the preset set the cell runs with ("default": the shipped one)."""
        for part in self.config.split(','):
            if part.startswith('presets='):
                return part.removeprefix('presets=')
        return 'default'


@lru_cache(maxsize=None)
def _engine_version(engine: str) -> str:
    try:
        return engine_class(engine).version()
    except ClothBenchError:  # an engine not on this machine: its cells are error rows
        return ''


def _shown(value: object) -> str:
    """Return a setting's value in a configuration name: on/off, numbers as %g, text as it is."""
    if isinstance(value, bool):
        return 'on' if value else 'off'
    return f'{value:g}' if isinstance(value, float) else str(value)


def set_values(
    presets: PresetSet | None, engine: str, cloth: str, primitive: str, model: str | None = None
) -> dict:
    """
    Return a preset set's values as overrides of the shipped preset ({} for the shipped set).

    model: the model that runs (an override's; None: the shipped preset's), whose entry the set
    gives. A cell carries its preset as overrides, so its run, key and results row say what it ran.
    """
    if presets is None or presets.is_default:
        return {}
    return load_preset(engine, cloth, primitive, presets.directory, model)


def set_label(presets: PresetSet | None, label: str) -> str:
    """Return a configuration's name with its preset set: "presets=identified[,...]"."""
    if presets is None or presets.is_default:
        return label
    return f'presets={presets.name}' + ('' if label == PRESET else f',{label}')


def config_label(grid: tuple[int, int] | None, overrides: dict) -> str:
    """Return a canonical name of a configuration: "preset" or "grid=6x8,param=value,..."."""
    parts = []
    if grid is not None:
        parts.append(f'grid={grid[0]}x{grid[1]}')
    for name in sorted(overrides):
        parts.append(f'{name}={_shown(overrides[name])}')
    return ','.join(parts) or PRESET


_BAG_NAME = r'^{cloth}(?:_(\d+))?_{primitive}$'


def find_bags(bag_dir: Path | None, cloth: str, primitive: str) -> list[tuple[int, Path]]:
    """
    (trial, path) of every bag for a cloth and task in `bag_dir` (default: the bundled bags).

    Names `<cloth>_<primitive>` (the bundled ones) and `<cloth>_<trial>_<primitive>` (the
    importer's) both count. ValueError if there is none.
    """
    base = Path(bag_dir) if bag_dir is not None else share_dir('bags')
    pattern = re.compile(_BAG_NAME.format(cloth=re.escape(cloth), primitive=re.escape(primitive)))
    found = []
    if base.is_dir():
        for path in sorted(base.iterdir()):
            m = pattern.match(path.name)
            if m and path.is_dir():
                found.append((int(m.group(1)) if m.group(1) else _bag_trial(path), path))
    if not found:
        raise InputError(
            f'bag directory {base}: no bag named {cloth}_{primitive} or'
            f' {cloth}_<trial>_{primitive}'
        )
    return sorted(found)


def _bag_trial(path: Path) -> int:
    try:
        with BagReader(path) as reader:
            trial = reader.trial
    except ClothBenchError:  # an unreadable bag is reported by the cell that runs it
        return 0
    return int(trial.trial) if trial is not None else 0


def with_inputs(cells: Sequence[Cell], task_file: str, cloth_mesh: str) -> list[Cell]:
    """
    Return the cells running a task file and a cloth mesh, each with its file's content hash.

    Both are read and checked here (one line, before any cell runs): the mesh is grasped at
    each cell's task's start.
    """
    if not task_file and not cloth_mesh:
        return list(cells)
    inputs: dict[tuple, dict[str, str]] = {}
    out = []
    for cell in cells:
        at = (cell.primitive, cell.grid, cell.cloth_size, cell.rate_hz)
        if at not in inputs:
            inputs[at] = study_inputs(cell.primitive, task_file, cloth_mesh, cell.grid,
                                      cell.cloth_size, cell.rate_hz)
        given = inputs[at]
        out.append(replace(cell, task_file=given['task_file'], task_sha256=given['task_sha256'],
                           cloth_mesh=given['cloth_mesh'], mesh_sha256=given['mesh_sha256']))
    return out


def _check_engines(engines: Iterable[str], overrides: dict[str, dict]) -> None:
    """Raise EngineError (a ValueError) on an unknown engine or a bad override, before any work."""
    for name in engines:
        cls = engine_class(name)
        cls.validate_params(overrides.get(name, {}))


def paper_cells(
    engines: Sequence[str] = DEFAULT_ENGINES,
    rates: Sequence[float] = DEFAULT_RATES,
    cloths: Sequence[str] = DEFAULT_CLOTHS,
    primitives: Sequence[str] = DEFAULT_PRIMITIVES,
    seeds: Sequence[int] = tuple(range(DEFAULT_SEEDS)),
    bag_dir: Path | None = None,
    grid: tuple[int, int] | None = None,
    overrides: dict[str, dict] | None = None,
    pacing: str = OPTIONS['pacing'].default,
    step_per_target: bool = False,
    keep_frames_seeds: Iterable[int] | None = None,
    presets: PresetSet | None = None,
    all_metrics: bool = False,
) -> list[Cell]:
    """
    Return the cells of the paper's layout.

    step_per_target: internal time step = 1 / rate, one engine step per target (the paper's
    frequency study), instead of the preset's time step. keep_frames_seeds: seeds whose per-frame
    scores are kept (default: the first seed). presets: a preset set instead of the shipped one.
    all_metrics: score every metric, not only the paper's CD/HD.
    """
    overrides = overrides or {}
    _check_engines(engines, overrides)
    keep = set(keep_frames_seeds) if keep_frames_seeds is not None else set(list(seeds)[:1])
    cells = []
    for cloth, primitive in product(cloths, primitives):
        for trial, bag in find_bags(bag_dir, cloth, primitive):
            for engine, rate, seed in product(engines, rates, seeds):
                params = dict(overrides.get(engine, {}))
                label = config_label(grid, params)
                if step_per_target:
                    params.update(timestep=1.0 / float(rate), substeps=1)
                    label = 'step=1/rate' if label == PRESET else f'{label},step=1/rate'
                params = {
                    **set_values(presets, engine, cloth, primitive, params.get('model')),
                    **params,
                }
                label = set_label(presets, label)
                cells.append(
                    Cell(
                        engine,
                        float(rate),
                        cloth,
                        primitive,
                        int(seed),
                        str(bag),
                        trial,
                        'paper',
                        label,
                        grid,
                        tuple(sorted(params.items())),
                        pacing,
                        seed in keep,
                        all_metrics=all_metrics or pacing == 'realtime',
                    )
                )
    return cells


def settings_cells(
    engines: Sequence[str] = DEFAULT_ENGINES,
    rate: float = SETTINGS_RATE,
    cloths: Sequence[str] = ('towel',),
    primitives: Sequence[str] = DEFAULT_PRIMITIVES,
    seeds: Sequence[int] = tuple(range(SETTINGS_SEEDS)),
    bag_dir: Path | None = None,
    axes: dict[str, list] | None = None,
    overrides: dict[str, dict] | None = None,
    presets: PresetSet | None = None,
    all_metrics: bool = False,
) -> list[Cell]:
    """
    Factorial sweep over the settings that cost time, per engine, at one rate.

    axes: parameter -> values ("grid" -> [(nx, nz), ...]); None as a value means the preset's.
    An axis naming a parameter that an engine does not have is skipped for that engine.
    """
    axes = dict(DEFAULT_SETTINGS_AXES if axes is None else axes)
    overrides = overrides or {}
    _check_engines(engines, overrides)
    grids = axes.pop('grid', [None])
    cells = []
    for engine in engines:
        schema = {p.name for p in engine_class(engine).params}
        names = [n for n in axes if n in schema]
        combos = []
        for grid in grids:
            for values in product(*(axes[n] for n in names)):
                params = dict(overrides.get(engine, {}))
                params.update({n: v for n, v in zip(names, values) if v is not None})
                engine_class(engine).validate_params(params)
                parts = [f'grid={grid[0]}x{grid[1]}' if grid else 'grid=default']
                for n, v in zip(names, values):
                    parts.append(f'{n}={PRESET if v is None else _shown(v)}')
                fixed = {k: v for k, v in overrides.get(engine, {}).items() if k not in names}
                if fixed:  # --set values shared by every configuration are part of its name
                    parts.append(config_label(None, fixed))
                combos.append(
                    (','.join(parts), tuple(grid) if grid else None, tuple(sorted(params.items())))
                )
        for cloth, primitive in product(cloths, primitives):
            for trial, bag in find_bags(bag_dir, cloth, primitive):
                model = overrides.get(engine, {}).get('model')
                base = set_values(presets, engine, cloth, primitive, model)
                for (label, grid, params), seed in product(combos, seeds):
                    cells.append(
                        Cell(
                            engine,
                            float(rate),
                            cloth,
                            primitive,
                            int(seed),
                            str(bag),
                            trial,
                            'settings',
                            set_label(presets, label),
                            grid,
                            tuple(sorted({**base, **dict(params)}.items())),
                            'lockstep',
                            False,
                            all_metrics=all_metrics,
                        )
                    )
    return cells


def estimated_cost(cell: Cell) -> float:
    """
    Return a rough cost of a cell in seconds of one core.

    Internal steps x a per-step cost, plus the work per target and per cell, fitted to the
    default 720-cell sweep on the direct study path (2 cores, 11 x 15 mesh): 0.66 ms per MuJoCo
    internal step on the fling, 1.4x that with the cloth on the table, 1.5x for PyBullet;
    0.09 ms per target and 0.4 s per cell. Realtime cells run the node graph: 0.5 ms per target.
    """
    duration = 7.4 if cell.primitive == 'dynamic' else 17.0  # settle phase + quintic part, s
    params = cell.params
    nx, nz = cell.grid or (11, 15)
    timestep = float(params.get('timestep', 0.002 if cell.engine == 'mujoco' else 0.0025))
    internal_steps = duration * max(cell.rate_hz, 1.0 / timestep)
    per_internal_step = (
        0.66e-3
        * (nx * nz / 165.0)
        * {'bullet': 1.5, 'newton': 5.0}.get(cell.engine, 1.0)
        * (1.4 if cell.primitive == 'quasi_static' else 1.0)
    )
    per_target = 0.5e-3 if cell.pacing == 'realtime' else 0.09e-3
    return internal_steps * per_internal_step + duration * cell.rate_hz * per_target + 0.4
