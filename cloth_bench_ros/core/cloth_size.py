"""
A cloth of another size than the benchmark's 0.5 x 0.7 m: its mesh, its grasp and its mass.

- Mesh: without a `--grid`, the mesh keeps the benchmark mesh's spacing (5 cm, the nearest whole
  number of cells along each side), so the parameters of every preset and identification, which
  are set for that spacing, describe the same material with no scaling; a given grid spans the
  cloth's extent, and `engines.base.params_for_grid` scales the parameters for its spacing.
- Grasp: the grippers hold the two top corners, at x = 0 and x = W. The benchmark's trajectories
  move the grippers in y and z only; its x positions (and the pre-grasp's inward moves of 20 mm
  and 2 mm) are kept relative to those corners, so the right gripper moves by W - 0.5 m; a
  recording's gripper targets are checked against that width (`targets_grasp_text`).
- Heights: the trajectory's heights and the table are the recording's, whatever the cloth: a
  shorter cloth reaches the table later, or never (the change of phase is found in the recording),
  and the length is bounded so that the cloth hangs clear of the table at the start.
- Mass: the engines' `mass` is the whole cloth's; a given total mass replaces it, else the
  preset's mass per area times the cloth's area (W L, or a `--cloth-mesh`'s area,
  core/cloth_mesh.py): one rule for both.
The benchmark's size gives exactly what no size gives.
"""

from __future__ import annotations

from typing import Any, Mapping

from cloth_bench_ros.core.scene import CLOTH_LENGTH, CLOTH_WIDTH, ClothGrid

BENCHMARK_SIZE = (CLOTH_WIDTH, CLOTH_LENGTH)
BENCHMARK_AREA = CLOTH_WIDTH * CLOTH_LENGTH  # m^2

Size = tuple[float, float]


def is_benchmark(size: Size | None) -> bool:
    """Return whether `size` is the benchmark's (None: not given, the benchmark's)."""
    return size is None or tuple(float(s) for s in size) == BENCHMARK_SIZE


def cloth_grid(grid: tuple[int, int] | None, size: Size | None) -> ClothGrid | None:
    """
    Return the mesh of a cloth of `size` (None: the engine's default mesh, as without a size).

    Without `grid`, the benchmark mesh's spacing: nx = round(W / 0.05) + 1, nz = round(L / 0.05)
    + 1.
    """
    if is_benchmark(size):
        return ClothGrid(*grid) if grid else None
    assert size is not None
    width, length = float(size[0]), float(size[1])
    if grid:
        return ClothGrid(int(grid[0]), int(grid[1]), width, length)
    dx, dz = ClothGrid().spacing
    nx = max(2, round(width / dx) + 1)
    nz = max(2, round(length / dz) + 1)
    return ClothGrid(nx, nz, width, length)


def grid_vertices(grid: tuple[int, int] | None, size: Size | None) -> int:
    """Return the vertex count of the mesh `cloth_grid` makes."""
    made = cloth_grid(grid, size) or ClothGrid()
    return made.nx * made.nz


def grasp_width(size: Size | None) -> float | None:
    """Return the distance between the grasped corners (None: the benchmark's, unchanged)."""
    return None if is_benchmark(size) else float(size[0])  # type: ignore[index]


def is_benchmark_cloth(size: Size | None, area: float | None = None) -> bool:
    """Return whether a cloth of `size`, or a mesh of `area` m^2, has the benchmark's area."""
    return is_benchmark(size) if area is None else float(area) == BENCHMARK_AREA


def cloth_mass(
    preset_mass: float, size: Size | None, mass: float | None, area: float | None = None
) -> float:
    """
    Return the cloth's total mass: `mass` if given, else the preset's per area times area.

    The area is a mesh's `area` (`--cloth-mesh`) if given, else the size's W L.
    """
    if mass is not None:
        return float(mass)
    if is_benchmark_cloth(size, area):
        return float(preset_mass)
    if area is not None:
        return float(preset_mass) / BENCHMARK_AREA * float(area)
    assert size is not None
    return float(preset_mass) / BENCHMARK_AREA * (float(size[0]) * float(size[1]))


def with_cloth_mass(
    params: Mapping[str, Any],
    default_mass: float,
    size: Size | None,
    mass: float | None,
    area: float | None = None,
) -> dict[str, Any]:
    """Return engine `params` with the cloth's total `mass` (unchanged for the benchmark cloth)."""
    out = dict(params)
    if mass is None and is_benchmark_cloth(size, area):
        return out
    out['mass'] = cloth_mass(float(out.get('mass', default_mass)), size, mass, area)
    return out


def cloth_record(size: Size | None, mass: float | None) -> dict[str, Any]:
    """Return what a summary records of the cloth: its size in m and its given mass (or None)."""
    width, length = BENCHMARK_SIZE if size is None else size
    return {'cloth_size': [float(width), float(length)], 'cloth_mass': mass}


def size_text(size: Size | None) -> str:
    """Return e.g. '0.40 x 0.60 m' (the benchmark's when None)."""
    width, length = BENCHMARK_SIZE if size is None else size
    return f'{width:.2f} x {length:.2f} m'


def mass_text(
    total: float,
    size: Size | None,
    mass: float | None,
    preset_mass: float,
    area: float | None = None,
) -> str:
    """Return where a cloth's total mass comes from, e.g. '0.2 kg (--cloth-mass)'."""
    if mass is not None:
        return f'{total:.4g} kg (--cloth-mass)'
    if is_benchmark_cloth(size, area):
        return f'{total:.4g} kg (the preset)'
    what = f"the mesh's {area:.4g} m^2" if area is not None else size_text(size)
    return f"{total:.4g} kg (the preset's {preset_mass / BENCHMARK_AREA:.4g} kg/m^2 times {what})"


GRASP_TOLERANCE = 0.025  # m: a recording's targets at the start pose or the pre-grasp agree


def targets_grasp_text(recorded: float | None, size: Size | None) -> str:
    """
    Return what a recording's gripper targets say of the grasp ('' when it has none).

    `recorded`: the x distance of its first two targets; the task's pre-grasp holds the corners
    W - 0.022 m apart (the start pose W).
    """
    if recorded is None:
        return ''
    width = float((size or BENCHMARK_SIZE)[0])
    if abs(recorded - (width - 0.022)) <= GRASP_TOLERANCE:
        return '' if is_benchmark(size) else (
            f"grasp: the recording's gripper targets agree ({recorded:.3f} m apart)"
        )
    return (
        f"grasp: the recording's gripper targets are {recorded:.3f} m apart, the simulated "
        f'corners {width:.3f} m ({size_text(size)} cloth): give the width with --cloth-size W,L'
    )


def grasp_text(size: Size | None) -> str:
    """Return the line that says where the grippers hold a resized cloth ('' for the benchmark)."""
    if is_benchmark(size):
        return ''
    assert size is not None
    return (
        f'grasp: the top corners, x = 0 and {float(size[0]):.3f} m; the benchmark trajectory in '
        'y, z and roll (its heights unchanged), its x moved with the corners'
    )
