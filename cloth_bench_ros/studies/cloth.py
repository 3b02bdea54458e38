"""The cloth a command runs: `--cloth-size`, `--cloth-mass`, `--cloth-mesh` checked; its lines."""

from __future__ import annotations

from typing import Mapping

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_mesh import ClothMesh, run_cloth
from cloth_bench_ros.core.cloth_size import (
    BENCHMARK_SIZE,
    cloth_grid,
    grasp_text,
    is_benchmark,
    mass_text,
    Size,
    size_text,
)
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.task_data import load_task, Task
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.engines.presets import sized_params
from cloth_bench_ros.errors import InputError


def cloth_choice(
    size: str | None, mass: float | None, overrides: Mapping[str, Mapping] | None = None
) -> tuple[Size | None, float | None]:
    """
    Return (W, L) or None and the mass of `--cloth-size` / `--cloth-mass`, checked.

    A mass given twice (`--cloth-mass` and `--set ENGINE.mass`) is refused in one line.
    """
    parsed = validation.parse_cloth_size(size or '', '--cloth-size')
    if mass is not None:
        mass = validation.number(mass, '--cloth-mass', *validation.CLOTH_MASS_RANGE, unit='kg')
        both = sorted(e for e, p in (overrides or {}).items() if 'mass' in p)
        if both:
            raise InputError(
                f"--cloth-mass and --set {both[0]}.mass both give the cloth's mass; give one"
            )
    return parsed, mass


def mesh_choice(
    path: str | None,
    grid: tuple[int, int] | None,
    size: Size | None,
    task: Task | str,
    rate_hz: float,
) -> ClothMesh | None:
    """
    Return the `--cloth-mesh` read and checked for `task` (None without one); one line if refused.

    Without a mesh the grid's start is checked against the task's (a recorded motion's grippers).
    """
    if path:
        for given, flag in ((grid, '--grid'), (size, '--cloth-size')):
            if given is not None:
                raise InputError(f'--cloth-mesh and {flag}: a mesh has its own vertices and '
                                 'size; give one')
    cloth = run_cloth(grid, size, path or None, task, rate_hz)
    return cloth if isinstance(cloth, ClothMesh) else None


def study_inputs(
    primitive: str,
    task_file: str,
    cloth_mesh: str,
    grid: tuple[int, int] | None,
    size: Size | None,
    rate_hz: float,
) -> dict[str, str]:
    """
    Return what a study's row records of its `--task` and `--cloth-mesh`: files and SHA-256s.

    Both are read and checked (one line if bad); '' for what is not given.
    """
    task = load_task(primitive, task_file or None)
    cloth = run_cloth(grid, size, cloth_mesh or None, task, rate_hz)
    return {
        'task_file': task_file,
        'task_sha256': task.sha256 if task_file else '',
        'cloth_mesh': cloth_mesh,
        'mesh_sha256': cloth.sha256 if isinstance(cloth, ClothMesh) else '',
    }


def mesh_line(mesh: ClothMesh) -> str:
    """Return the line that says a run's `--cloth-mesh`: size, spacing, grasp."""
    return (
        f'cloth: mesh {mesh.source}, {len(mesh.rest)} vertices, {len(mesh.triangles)} '
        f'triangles, {mesh.area:.4g} m^2; material of a grid of spacing ratio '
        f"{mesh.spacing_ratio():.4g} (the benchmark grid's 1); grasped vertices "
        f'{mesh.left_corner} and {mesh.right_corner}'
    )


def cloth_lines(
    masses: Mapping[str, tuple[float, float]],
    size: Size | None,
    mass: float | None,
    grid: tuple[int, int] | None,
    mesh: ClothMesh | None = None,
) -> list[str]:
    """
    Return what a run says of a cloth of another size or mass ([] for the benchmark's cloth).

    `masses`: per engine, (the total mass it runs with, its preset's mass).
    """
    if mesh is not None:
        return [mesh_line(mesh), 'mass ' + ', '.join(
            f'{engine} {mass_text(total, None, mass, preset, mesh.area)}'
            for engine, (total, preset) in masses.items()
        )]
    if mass is None and is_benchmark(size):
        return []
    made = cloth_grid(grid, size) or ClothGrid()
    how = 'as --grid' if grid else "at the benchmark mesh's 5 cm spacing"
    lines = [
        f'cloth: {size_text(size)}{" (the benchmark)" if size is None else ""}, '
        f'mesh {made.nx} x {made.nz} ({how}); mass '
        + ', '.join(
            f'{engine} {mass_text(total, size, mass, preset)}'
            for engine, (total, preset) in masses.items()
        )
    ]
    grasp = grasp_text(size)
    if grasp:
        lines.append(grasp)
    return lines


def cloth_name(size: Size | None, mass: float | None) -> str:
    """Return a short label of the cloth, e.g. '0.40 x 0.60 m, 0.2 kg' (no mass: the size)."""
    text = size_text(size if size is not None else BENCHMARK_SIZE)
    return text + (f', {mass:g} kg' if mass is not None else '')


def engine_masses(
    params_of: Mapping[str, Mapping],
    size: Size | None,
    mass: float | None,
    area: float | None = None,
) -> dict[str, tuple[float, float]]:
    """Return per engine (the cloth's total mass it runs with, the mass of its `params`)."""
    out = {}
    for engine, params in params_of.items():
        total = sized_params(engine, dict(params), size, mass, area).get('mass')
        own = engine_class(engine).validate_params(dict(params)).get('mass')
        if total is not None and own is not None:
            out[engine] = (float(total), float(own))
    return out
