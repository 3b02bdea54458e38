"""
The stress suite's cases: scenes that break cloth simulators, with each engine's parameter names.

A case is an engine, a primitive, a rate and overrides on top of the towel preset, with the
primitive's target trajectory possibly transformed (time-compressed, pushed lower, a gripper
jump); studies/stress.py runs them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from typing import Sequence

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.cloth_mesh import run_cloth
from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.presets import PresetSet
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.studies.cells import set_values
from cloth_bench_ros.studies.cloth import study_inputs

MAX_CASE_WALL_S = 120.0


@dataclass(frozen=True)
class StressCase:
    name: str
    engine: str
    description: str
    primitive: str = OPTIONS['primitive'].default
    rate_hz: float = OPTIONS['rate_hz'].default
    params: dict = field(default_factory=dict)  # overrides on top of the towel preset of the task
    grid: tuple[int, int] | None = None
    time_compression: float = 1.0  # the trajectory is played this many times faster
    drag_height: float | None = (
        None  # m: the grippers' lowest height above the table top (< 0: into it)
    )
    jump: float = 0.0  # m: the right gripper jumps this far outwards (x) 1 s into the quintic part
    max_wall_s: float = MAX_CASE_WALL_S
    task_file: str = ''  # --task: a task file's motion instead of the shipped task of `primitive`
    cloth_mesh: str = ''  # --cloth-mesh: the cloth as a mesh file instead of the grid


def _one_step(rate: float) -> dict:
    """One internal step per target (the paper's frequency study)."""
    return {'timestep': 1.0 / rate, 'substeps': 1}


def default_cases(engines: Sequence[str] = ('mujoco', 'bullet', 'newton')) -> list[StressCase]:
    """Return the suite: the hard cases and more, with each engine's own parameter names."""
    cases: list[StressCase] = []
    for e in engines:
        stiff = (
            {'model': 'edges', 'edge_stiffness': 1e6}
            if e == 'mujoco'
            else (
                {'elastic': 1e5, 'bending': 1e5}
                if e == 'bullet'
                else (
                    {'tri_stiffness': 1e6, 'tri_area_stiffness': 1e6, 'spring_stiffness': 1e5}
                    if e == 'newton'
                    else {}
                )
            )
        )
        damping = 'tri_damping' if e == 'newton' else 'damping'  # Newton's preset model is vbd
        common = [
            StressCase(
                'fling_10hz',
                e,
                'fling at 10 Hz, one internal step per target (dt = 0.1 s)',
                'dynamic',
                10.0,
                _one_step(10.0),
            ),
            StressCase(
                'fling_100hz_one_step',
                e,
                'fling at 100 Hz, one internal step per target (dt = 0.01 s)',
                'dynamic',
                100.0,
                _one_step(100.0),
            ),
            StressCase(
                'stiff_cloth',
                e,
                'very stiff cloth ('
                + ', '.join(f'{k}={v:g}' for k, v in stiff.items() if not isinstance(v, str))
                + '), fling at 100 Hz with the preset time step',
                'dynamic',
                100.0,
                stiff,
            ),
            StressCase(
                'light_cloth',
                e,
                'very light cloth (mass 1 g), fling at 100 Hz',
                'dynamic',
                100.0,
                {'mass': 0.001},
            ),
            StressCase(
                'heavy_cloth',
                e,
                'very heavy cloth (mass 100 kg), fling at 100 Hz',
                'dynamic',
                100.0,
                {'mass': 100.0},
            ),
            StressCase(
                'fast_drag_onto_table',
                e,
                'quasi-static drag played 5x faster, grippers lowered to 2 cm above the table top',
                'quasi_static',
                100.0,
                {},
                time_compression=5.0,
                drag_height=0.02,
            ),
            StressCase(
                'fast_drag_into_table',
                e,
                'quasi-static drag played 5x faster, grippers driven 2 cm into the table',
                'quasi_static',
                100.0,
                {},
                time_compression=5.0,
                drag_height=-0.02,
            ),
            StressCase(
                'large_dt_high_damping',
                e,
                'dt = 0.1 s (10 Hz, one step per target) with damping 100',
                'dynamic',
                10.0,
                {**_one_step(10.0), damping: 100.0},
            ),
            StressCase(
                'fine_mesh_one_step',
                e,
                'fine 21 x 29 mesh, fling at 100 Hz with one step per target',
                'dynamic',
                100.0,
                _one_step(100.0),
                grid=(21, 29),
            ),
            StressCase(
                'gripper_jump',
                e,
                'the right gripper jumps 0.3 m outwards in one step (tears the cloth)',
                'dynamic',
                100.0,
                {},
                jump=0.3,
            ),
            StressCase(
                'one_solver_iteration',
                e,
                'fling at 100 Hz, 1 solver iteration per internal step',
                'dynamic',
                100.0,
                {'solver_iterations': 1},
            ),
            StressCase(
                'self_collision_fling',
                e,
                'fling at 100 Hz with cloth self-collision',
                'dynamic',
                100.0,
                {'self_collision': True},
            ),
            StressCase(
                'no_damping_one_step',
                e,
                'fling at 100 Hz, one step per target, no damping',
                'dynamic',
                100.0,
                {**_one_step(100.0), damping: 0.0},
            ),
        ]
        cases += common
    return cases


def select_cases(
    engines: Sequence[str],
    names: Sequence[str] | None = None,
    max_wall_s: float | None = None,
    presets: PresetSet | None = None,
    task_file: str = '',
    cloth_mesh: str = '',
) -> list[StressCase]:
    """
    Return the suite for `engines`; optionally only `names`, a time budget, a preset set.

    `task_file`, `cloth_mesh`: every case runs that task's motion and that cloth (checked here,
    one line); a case of its own grid is left out with a mesh.
    """
    for name in engines:
        engine_class(name)
    cases = default_cases(engines)
    if names:
        known = {c.name for c in cases}
        unknown = sorted(set(names) - known)
        if unknown:
            raise InputError(
                f'unknown stress case {", ".join(unknown)} (known: {", ".join(sorted(known))})'
            )
        cases = [c for c in cases if c.name in names]
    if max_wall_s is not None:
        if not (math.isfinite(max_wall_s) and max_wall_s > 0):
            raise InputError(f'--max-wall-s must be a number of seconds > 0, got {max_wall_s}')
        cases = [replace(c, max_wall_s=max_wall_s) for c in cases]
    if task_file or cloth_mesh:
        cases = [replace(c, task_file=task_file, cloth_mesh=cloth_mesh)
                 for c in cases if not (cloth_mesh and c.grid)]
        for case in cases:
            case_cloth(case)  # a bad task file or mesh: one line, before any case runs
    # A preset set's values (its entry of the preset's model) go in as overrides of the towel
    # preset, under each case's own (a case may switch the model: that is what it stresses).
    return [
        replace(c, params={**set_values(presets, c.engine, 'towel', c.primitive), **c.params})
        for c in cases
    ]


def case_task(case: StressCase):
    """Return the Task a case runs: its task file's, else the shipped one of its primitive."""
    return load_task(case.primitive, case.task_file or None)


def case_cloth(case: StressCase):
    """Return the cloth a case runs (core/cloth_mesh.py run_cloth; None: the engine's grid)."""
    return run_cloth(case.grid, None, case.cloth_mesh or None, case_task(case), case.rate_hz)


def case_inputs(case: StressCase) -> dict:
    """Return what a row records of a case's task file and mesh (file and SHA-256; '': none)."""
    return study_inputs(case.primitive, case.task_file, case.cloth_mesh, case.grid, None,
                        case.rate_hz)


def case_targets(case: StressCase):
    """(left, right, quintic_index, dt) of a case: the primitive's targets, transformed."""
    # Sampled every time_compression / rate s of trajectory time, played one sample per 1 / rate.
    samples_per_s = case.rate_hz / case.time_compression
    targets = full_targets(case_task(case), samples_per_s)
    left, right = targets.left.copy(), targets.right.copy()
    q = targets.quintic_index
    if case.drag_height is not None:
        z0 = float(left[q, 2])
        lowest = min(left[q:, 2].min(), right[q:, 2].min())
        scale = (z0 - (scene.TABLE_TOP_Z + case.drag_height)) / (z0 - lowest)
        for g in (left, right):
            g[q:, 2] = z0 + (g[q:, 2] - z0) * scale
    if case.jump:
        k = q + int(round(1.0 * samples_per_s))
        right[k:, 0] += case.jump
    return left, right, q, 1.0 / case.rate_hz
