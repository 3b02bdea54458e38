"""
How converged a synthetic reference is: its trajectory under refined numerical settings.

A reference model (config/synth.yaml: MuJoCo shell; config/synth_newton_vbd.yaml: Newton VBD)
has settings that should not change the cloth it makes: solver iterations, the step rate and the
mesh resolution. Each is refined in turn from the shipped setting (iterations x2, x4, ...; rate
x2, ...; a finer grid), the reference run through the whole trial (its vertices at every 30 fps
frame, no camera), and each run compared with the one before it on its axis:

- trajectory change: per frame, the mean L1 distance from one run's vertices to the other's cloth
  surface (its grid's triangles, core/surface_distance.py, so that meshes of different resolution
  compare as surfaces), both ways, the larger; the mean over the frames and the largest frame;
- hanging length: the cloth's vertical extent at frame 0, after the settle.

An axis has converged when a refinement changes the trajectory by less than TOLERANCE_M on
average and the hanging length by less than HANG_TOLERANCE_M.

What a refinement does to the scores: with `scored` engines, each engine's shipped preset runs on
the tested grid through the same trial (at SCORE_RATE_HZ, so that frames fall on steps) and its
vertices' mean L1 distance to every run's surface is reported, so a reference's numerical error
can be read in the units of the benchmark's scores.

A finer grid must describe the same cloth: the parameters that depend on the spacing are scaled
by the engines' one rule (`params_for_grid`: the MuJoCo shell's edge time constant, Newton's
contact stiffness), and the grid axis runs at the rate its finest level needs for that time
constant (at least two internal steps), its first level compared with the
shipped grid at the same rate.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import json
from pathlib import Path
import time
from typing import Any, Callable

from cloth_bench_ros.command_options import COMMAND_FLAGS
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.surface_distance import grid_faces, point_to_surface, TriangleMesh
from cloth_bench_ros.data.synth import reference_config, simulate_reference, SynthConfig
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.base import params_for_grid
from cloth_bench_ros.engines.mujoco_cloth import TIMECONST_SLACK
from cloth_bench_ros.engines.presets import load_preset
from cloth_bench_ros.errors import InputError
import numpy as np

TOLERANCE_M = 0.002  # mean trajectory change between successive refinements
HANG_TOLERANCE_M = 0.005
AXES = ('iterations', 'rate', 'grid')
SCORE_RATE_HZ = 300.0  # the engines scored against each run: every frame falls on a step


@dataclass(frozen=True)
class Variant:
    """One run of the study: the reference with one setting refined `level` times."""

    axis: str  # '' for the shipped settings
    level: int
    config: SynthConfig = field(compare=False)
    previous: str = ''  # label of the run it is compared with ('' for the shipped one)

    @property
    def label(self) -> str:
        return label(self.axis, self.level)

    def describe(self) -> str:
        p = self.config.params
        text = (
            f'{self.config.grid[0]}x{self.config.grid[1]}, {self.config.rate_hz:g} Hz,'
            f' {p.get("solver_iterations")} iterations'
        )
        if 'edge_timeconst' in p:
            text += f', edges {1000 * float(p["edge_timeconst"]):.3g} ms'
        return text


def label(axis: str, level: int) -> str:
    """Return a run's name: `shipped`, or the axis and how many times it was refined."""
    return 'shipped' if not axis or not level else f'{axis}+{level}'


def refined(config: SynthConfig, axis: str, level: int) -> SynthConfig:
    """
    Return `config` with one setting refined `level` times.

    Iterations x2 each; the rate x2 with the longest internal step /2 (so the step the engine
    takes halves too); the grid's spacing /1.5, with the parameters that depend on the spacing
    scaled by the engines' one rule (`params_for_grid`).
    """
    if axis == 'iterations':
        iterations = int(config.params['solver_iterations']) * 2**level
        return replace(config, params={**config.params, 'solver_iterations': iterations})
    if axis == 'rate':
        params = dict(config.params)
        if 'timestep' in params:
            params['timestep'] = float(params['timestep']) / 2**level
        return replace(config, rate_hz=config.rate_hz * 2**level, params=params)
    if axis == 'grid':
        nx, nz = config.grid
        scale = 1.5**level  # 31 x 43 -> 46 x 64 -> 69 x 95: spacing 1.7 -> 1.1 -> 0.7 cm
        grid = (round((nx - 1) * scale) + 1, round((nz - 1) * scale) + 1)
        params = params_for_grid(
            engine_class(config.engine), config.params, config.rate_hz, ClothGrid(*grid),
            ClothGrid(nx, nz),
        )
        return replace(config, grid=grid, params=params)
    raise InputError(f'unknown axis {axis!r} (valid: {", ".join(AXES)})')


def grid_rate_level(config: SynthConfig, levels: int) -> int:
    """Return the rate doublings the finest grid needs: edge time constant >= 2 internal steps."""
    timeconst = refined(config, 'grid', levels).params.get('edge_timeconst')
    doublings = 0
    slack = 1 + TIMECONST_SLACK  # within it the engine floors the time constant at 2 steps
    while timeconst is not None and 2.0 / (config.rate_hz * 2**doublings) > timeconst * slack:
        doublings += 1
    return doublings


def variants(base: SynthConfig, axes: tuple[str, ...], levels: int) -> list[Variant]:
    """Return the shipped run and `levels` refinements along each axis, each with its baseline."""
    runs = {'shipped': Variant('', 0, base)}
    for axis in axes:
        start, start_label = base, 'shipped'
        if axis == 'grid' and (doublings := grid_rate_level(base, levels)):
            start, start_label = refined(base, 'rate', doublings), label('rate', doublings)
            runs.setdefault(start_label, Variant('rate', doublings, start, 'shipped'))
        for n in range(1, levels + 1):
            previous = start_label if n == 1 else label(axis, n - 1)
            runs[label(axis, n)] = Variant(axis, n, refined(start, axis, n), previous)
    return list(runs.values())


def trajectory(variant: Variant) -> tuple[np.ndarray, float]:
    """Run the reference; return its vertices at every frame (frames, n, 3) and the seconds."""
    start = time.perf_counter()
    frames = [v.astype(np.float32) for _, v in simulate_reference(variant.config)]
    return np.stack(frames), time.perf_counter() - start


def surface_distance(points: np.ndarray, vertices: np.ndarray, grid: tuple[int, int]) -> float:
    """Return the mean L1 distance from points to a grid's cloth surface (its triangles)."""
    return float(point_to_surface(points, vertices, grid_faces(*grid)).mean())


def trajectory_change(
    a: np.ndarray, grid_a: tuple[int, int], b: np.ndarray, grid_b: tuple[int, int]
) -> np.ndarray:
    """Per frame: one run's vertices to the other's surface (one-sided L1 CD), the larger way."""
    return np.array(
        [
            max(
                surface_distance(va, vb, grid_b),
                surface_distance(vb, va, grid_a),
            )
            for va, vb in zip(a, b)
        ]
    )


def hanging_length(frames: np.ndarray) -> float:
    """Return the cloth's vertical extent at frame 0 (it hangs from the grippers, settled)."""
    return float(np.ptp(frames[0][:, 2]))


def engine_frames(engine: str, base: SynthConfig) -> np.ndarray:
    """Run an engine's shipped preset on the tested grid through the trial: vertices per frame."""
    tested = ClothGrid()
    config = replace(
        base,
        engine=engine,
        grid=(tested.nx, tested.nz),
        rate_hz=SCORE_RATE_HZ,
        params=load_preset(engine, base.cloth, base.primitive),
    )
    return np.stack([v for _, v in simulate_reference(config)])


def engine_scores(
    engines: dict[str, np.ndarray], run: np.ndarray, grid: tuple[int, int]
) -> dict[str, float]:
    """Return each engine's score against one run: its vertices' mean distance to its surface."""
    per_frame: dict[str, list[float]] = {name: [] for name in engines}
    for k, vertices in enumerate(run):
        cloth = TriangleMesh(vertices, grid_faces(*grid))
        for name, frames in engines.items():
            per_frame[name].append(float(cloth.distances(frames[k]).mean()))
    return {name: float(np.mean(values)) for name, values in per_frame.items()}


def _simulate(variant: Variant, out_dir: str) -> dict:
    """Run one variant on a worker and keep its trajectory in out_dir (a rerun reuses it)."""
    path = Path(out_dir) / f'{variant.label}.npz'
    if path.exists():
        saved = np.load(path)
        return {'path': str(path), 'seconds': float(saved['seconds'])}
    frames, seconds = trajectory(variant)
    tmp = path.with_suffix('.tmp.npz')
    np.savez(tmp, frames=frames, seconds=seconds)
    tmp.replace(path)
    return {'path': str(path), 'seconds': seconds}


@dataclass
class ConvergenceStudy:
    """The study of one reference, cloth and task; rows() is its table."""

    reference: str
    cloth: str
    primitive: str
    axes: tuple[str, ...] = AXES
    levels: int = COMMAND_FLAGS['levels'].default
    duration: float | None = None  # s of the quintic part (None: the whole trial)
    overrides: dict[str, Any] = field(default_factory=dict)  # of the base (tests: a coarse grid)
    scored: tuple[str, ...] = ()  # engines whose presets are scored against every run
    device: str | None = None  # the Newton reference's device (None: its default)
    runs: dict[str, dict] = field(default_factory=dict)

    def variants(self) -> list[Variant]:
        base = reference_config(
            self.cloth,
            self.primitive,
            reference=self.reference,
            duration=self.duration,
            **self.overrides,
        )
        if self.device is not None:
            if base.engine != 'newton':
                raise ValueError(
                    f'--device: the {self.reference} reference runs on {base.engine}, not Newton'
                )
            base = replace(base, params={**base.params, 'device': self.device})
        return variants(base, self.axes, self.levels)

    def run(self, out_dir: Path, executor: Callable[..., None]) -> None:
        """Simulate every variant through `executor(func, items, on_result, on_crash, args)`."""
        out_dir.mkdir(parents=True, exist_ok=True)
        todo = self.variants()

        def on_result(variant: Variant, result: dict) -> None:
            self.runs[variant.label] = result

        def on_crash(variant: Variant, message: str) -> None:
            self.runs[variant.label] = {'error': message}

        executor(_simulate, todo, on_result, on_crash, (str(out_dir),))

    def rows(self) -> list[dict[str, Any]]:
        """One row per run: its settings, wall time, hanging length and change from the last."""
        by_label = {v.label: v for v in self.variants()}
        frames = {
            label: np.load(run['path'])['frames']
            for label, run in self.runs.items()
            if 'path' in run
        }
        engines = {
            name: engine_frames(name, by_label['shipped'].config) for name in self.scored
        }
        rows = []
        for variant in by_label.values():
            row: dict[str, Any] = {
                'run': variant.label,
                'settings': variant.describe(),
                'seconds': self.runs.get(variant.label, {}).get('seconds'),
                'error': self.runs.get(variant.label, {}).get('error'),
            }
            if variant.label in frames:
                row['hanging_length_m'] = hanging_length(frames[variant.label])
                if engines:
                    row['scores_m'] = engine_scores(
                        engines, frames[variant.label], variant.config.grid
                    )
            previous = by_label.get(variant.previous)
            if previous is not None and {variant.label, previous.label} <= set(frames):
                change = trajectory_change(
                    frames[previous.label], previous.config.grid,
                    frames[variant.label], variant.config.grid,
                )
                hang = abs(row['hanging_length_m'] - hanging_length(frames[previous.label]))
                row.update(
                    compared_with=previous.label,
                    change_mean_m=float(change.mean()),
                    change_max_m=float(change.max()),
                    hang_change_m=hang,
                    converged=bool(change.mean() < TOLERANCE_M and hang < HANG_TOLERANCE_M),
                )
            rows.append(row)
        return rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    """Return the study's table as text (mm); scored engines' CD in the last columns."""
    scored = list(next((r['scores_m'] for r in rows if r.get('scores_m')), {}))
    lines = [
        f'{"run":<14} {"settings":<46} {"s":>7} {"hang mm":>8} {"vs":<14}'
        f' {"mean mm":>8} {"max mm":>7} {"d hang":>7}  {"converged":<9}'
        + ''.join(f' {"CD " + name:>12}' for name in scored)
    ]
    for r in rows:
        mm = (lambda key: f'{1000 * r[key]:.1f}' if r.get(key) is not None else '-')  # noqa: E731
        seconds = f'{r["seconds"]:.0f}' if r.get('seconds') is not None else '-'
        converged = 'error' if r.get('error') else str(r.get('converged', ''))
        scores = r.get('scores_m') or {}
        lines.append(
            f'{r["run"]:<14} {r["settings"]:<46} {seconds:>7} {mm("hanging_length_m"):>8}'
            f' {r.get("compared_with", ""):<14} {mm("change_mean_m"):>8} {mm("change_max_m"):>7}'
            f' {mm("hang_change_m"):>7}  {converged:<9}'
            + ''.join(
                f' {1000 * scores[name]:>12.1f}' if name in scores else f' {"-":>12}'
                for name in scored
            )
        )
    return '\n'.join(lines)


def save(rows: list[dict[str, Any]], study: ConvergenceStudy, path: Path) -> None:
    """Write the study's rows and what it was, as JSON."""
    doc = {
        'reference': study.reference,
        'cloth': study.cloth,
        'primitive': study.primitive,
        'duration': study.duration,
        'tolerance_m': TOLERANCE_M,
        'hang_tolerance_m': HANG_TOLERANCE_M,
        'scored': list(study.scored),
        'score_rate_hz': SCORE_RATE_HZ,
        'rows': rows,
    }
    path.write_text(json.dumps(doc, indent=1) + '\n', encoding='utf-8')
