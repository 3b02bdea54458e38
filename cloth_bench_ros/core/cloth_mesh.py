"""
A cloth from a triangle mesh file (`--cloth-mesh`): its shape, grasp, area and spacing.

- File: OBJ, PLY or STL, read by trimesh (no processing of its own: vertices at one position are
  merged, first occurrence first, so an STL's triangle soup is one surface and an OBJ or PLY keeps
  its vertex order). The mesh is the cloth in its start placement, in the scene's frame (metres),
  or, with a recorded motion, in the recording's frame: it is then moved into the scene's by the
  motion's own turn and translation (`to_scene`), as the grippers are.
- Checked, one line each: readable, finite, triangles only; no degenerate triangle (a repeated
  vertex or an area under DEGENERATE_AREA of the mean), no triangle twice, no edge shared by more
  than two triangles, one connected part, at most `validation.MAX_GRID_VERTICES` vertices.
- Grasp: the vertices nearest the grippers' start positions, each within GRASP_REACH; recorded
  grippers that start further apart than the grasped vertices (or a grid's grasped edge) allow are
  refused (`check_start`).
- Spacing: sqrt(2 area / triangles), the cell of a grid with the same triangle area; over the
  benchmark grid's it scales that grid's (dx, dz), and the material follows by the rule of
  `--grid` (engines/base.py `params_for_grid`): a finer mesh of one garment is the same cloth.
"""

from __future__ import annotations

from dataclasses import dataclass
import hashlib
import io
import math
from pathlib import Path
from typing import Any

from cloth_bench_ros import validation
from cloth_bench_ros.core.cloth_size import cloth_grid, grasp_width
from cloth_bench_ros.core.scene import CLOTH_WIDTH, ClothGrid
from cloth_bench_ros.core.trajectory import as_task, full_targets
from cloth_bench_ros.errors import InputError, user_path
import numpy as np

FORMATS = ('.obj', '.ply', '.stl')
GRASP_REACH = 0.01  # m: a grasped vertex lies this close to its gripper's start position
GRASP_SLACK = 0.01  # m: recorded grippers may start this much further apart than the cloth allows
DEGENERATE_AREA = 1e-6  # a triangle under this fraction of the mean triangle area is degenerate
# The mesh's area and its spacing ratio are rounded to these, so that a mesh of the benchmark's
# grid is that grid's cloth exactly (a sum of triangle areas differs in the last bits).
AREA_DIGITS = 12  # decimals of m^2
RATIO_DIGITS = 6  # a float32 file (PLY, STL) of a 5 cm mesh is the 5 cm material


@dataclass(frozen=True, eq=False)
class ClothMesh:
    """A single-layer triangle mesh in its start placement with its two grasped vertices."""

    source: str  # the file as the user named it
    sha256: str  # of the file's bytes
    rest: np.ndarray  # (n, 3) m
    triangles: np.ndarray  # (m, 3) vertex indices
    left_corner: int
    right_corner: int

    def vertices(self) -> np.ndarray:
        """Rest positions, shape (n, 3), in metres."""
        return self.rest.copy()

    def faces(self) -> np.ndarray:
        """Triangles, shape (m, 3), vertex indices."""
        return self.triangles.copy()

    @property
    def area(self) -> float:
        """Return the mesh's area in m^2 (rounded to AREA_DIGITS decimals)."""
        return round(float(triangle_areas(self.rest, self.triangles).sum()), AREA_DIGITS)

    @property
    def spacing_length(self) -> float:
        """sqrt(2 area / triangles) in m: the cell side of a grid with this triangle area."""
        return math.sqrt(2.0 * self.area / len(self.triangles))

    @property
    def spacing(self) -> tuple[float, float]:
        """
        Return the (dx, dz) of the benchmark grid scaled by this mesh's `spacing_ratio`.

        The mesh is then given the material of a grid of that spacing (engines/base.py
        `params_for_grid`, one rule for `--grid` and `--cloth-mesh`).
        """
        dx, dz = ClothGrid().spacing
        ratio = self.spacing_ratio()
        return ratio * dx, ratio * dz

    def spacing_ratio(self) -> float:
        """Return `spacing_length` over the benchmark grid's, rounded to RATIO_DIGITS."""
        dx, dz = ClothGrid().spacing
        return round(self.spacing_length / math.sqrt(dx * dz), RATIO_DIGITS)

    def grasp_weights(self) -> np.ndarray:
        """Per vertex, 0 at the left grasp to 1 at the right: its projection on their line."""
        a, b = self.rest[self.left_corner], self.rest[self.right_corner]
        line = b - a
        return np.clip((self.rest - a) @ line / float(line @ line), 0.0, 1.0)

    @property
    def grid(self) -> ClothGrid | None:
        """
        Return the ClothGrid this mesh is, vertex for vertex and triangle for triangle, or None.

        Engines build a grid's springs and slab by the grid's rows and columns, which a general
        mesh has not: a mesh that is a grid gets them, so it is that grid's cloth exactly.
        """
        n, nx = len(self.rest), self.right_corner + 1
        if self.left_corner != 0 or nx < 2 or n % nx or n // nx < 2:
            return None
        width = float(self.rest[self.right_corner, 0])
        top, bottom = float(self.rest[0, 2]), float(self.rest[-1, 2])
        try:
            grid = ClothGrid(nx, n // nx, width, top - bottom, top)
        except InputError:
            return None
        if np.array_equal(grid.faces(), self.triangles) and np.allclose(
            grid.vertices(), self.rest, rtol=0.0, atol=1e-12
        ):
            return grid
        return None

    def record(self) -> dict[str, Any]:
        """Return what a summary records of the mesh: its file, content hash, size and area."""
        return {'file': self.source, 'sha256': self.sha256, 'vertices': len(self.rest),
                'triangles': len(self.triangles), 'area_m2': self.area}


Cloth = ClothGrid | ClothMesh


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Return the area of each triangle, shape (m,)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def read_cloth_mesh(
    path: str | Path, left: np.ndarray, right: np.ndarray, to_scene: np.ndarray | None = None
) -> ClothMesh:
    """
    Read and check a cloth mesh; grasped at the vertices nearest `left` and `right`.

    `to_scene`: a 4x4 rigid transform from the file's frame to the scene's (a recorded motion's),
    applied to the vertices first. InputError, one line naming the file, for anything the
    benchmark cannot run as a cloth.
    """
    name = f'cloth mesh {path}'
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f'{name}: not an OBJ, PLY or STL file (by its extension {suffix!r})')
    with user_path(path):
        data = Path(path).read_bytes()
    vertices, faces = _load(data, suffix, name)
    vertices, faces = _merged(vertices, faces)
    check_mesh(vertices, faces, name)
    if to_scene is not None:
        vertices = vertices @ to_scene[:3, :3].T + to_scene[:3, 3]
    corners = [_grasped(vertices, np.asarray(p, float), side, name)
               for p, side in ((left, 'left'), (right, 'right'))]
    if corners[0] == corners[1]:
        raise InputError(f'{name}: both grippers start nearest vertex {corners[0]}')
    return ClothMesh(str(path), hashlib.sha256(data).hexdigest(), vertices, faces, *corners)


def _load(data: bytes, suffix: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Return the file's vertices and triangles as trimesh reads them, unprocessed."""
    import trimesh  # lazy: +0.6 s at an engine's start, not in .venv-ros; mesh files only

    try:
        loaded: Any = trimesh.load(
            io.BytesIO(data), file_type=suffix[1:], force='mesh', process=False)
        vertices = np.asarray(loaded.vertices, dtype=np.float64)
        faces = np.asarray(loaded.faces, dtype=np.int64)
    except Exception as exc:  # the reader's failure on a file is that file's fault
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f'{name}: not readable as {suffix[1:].upper()} ({text})') from None
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise InputError(f'{name}: no triangles')
    return vertices, faces


def _merged(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the mesh with vertices at one position merged (first occurrence, in order)."""
    if not np.isfinite(vertices).all():
        return vertices, faces  # check_mesh says it
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(vertices):
        return vertices, faces
    order = np.argsort(first)
    new_index = np.empty(len(order), dtype=np.int64)
    new_index[order] = np.arange(len(order))
    return vertices[first[order]], new_index[inverse.ravel()][faces]


def check_mesh(vertices: np.ndarray, faces: np.ndarray, name: str) -> None:
    """InputError, one line, unless the mesh is one manifold surface of sound triangles."""
    from scipy.sparse import coo_matrix, csgraph  # lazy: +0.34 s at an engine's start

    n, limit = len(vertices), validation.MAX_GRID_VERTICES
    if n > limit:
        raise InputError(f'{name}: {n} vertices, more than the {limit} allowed')
    if not np.isfinite(vertices).all():
        raise InputError(f'{name}: non-finite vertex coordinates')
    if faces.min() < 0 or faces.max() >= n:
        raise InputError(f'{name}: a triangle names a vertex that is not in the file')
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (
        faces[:, 0] == faces[:, 2])
    areas = triangle_areas(vertices, faces)
    degenerate = np.flatnonzero(repeated | (areas < DEGENERATE_AREA * areas.mean()))
    if len(degenerate):
        raise InputError(f'{name}: {len(degenerate)} degenerate triangles (no area), the first '
                         f'is triangle {degenerate[0]}')
    _, counts = np.unique(np.sort(faces, axis=1), axis=0, return_counts=True)
    if (counts > 1).any():
        raise InputError(f'{name}: {int((counts > 1).sum())} triangles given more than once')
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    shared, per_edge = np.unique(edges, axis=0, return_counts=True)
    if (per_edge > 2).any():
        a, b = shared[per_edge > 2][0]
        raise InputError(f'{name}: {int((per_edge > 2).sum())} non-manifold edges (an edge of '
                         f'more than two triangles), the first between vertices {a} and {b}')
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    parts, _ = csgraph.connected_components(graph, directed=False)
    if parts > 1:
        raise InputError(f'{name}: {parts} separate parts (or vertices of no triangle); a cloth '
                         'is one connected surface')


def _grasped(vertices: np.ndarray, start: np.ndarray, side: str, name: str) -> int:
    """Return the vertex nearest a gripper's start; InputError beyond GRASP_REACH."""
    distance = np.linalg.norm(vertices - start, axis=1)
    index = int(distance.argmin())
    if distance[index] > GRASP_REACH:
        where = ', '.join(f'{v:.3f}' for v in start)
        raise InputError(
            f'{name}: no vertex within {GRASP_REACH * 100:g} cm of the {side} gripper'
            f"'s start ({where}) m: the nearest is {distance[index] * 1000:.1f} mm away"
        )
    return index


def run_cloth(
    grid: tuple[int, int] | None,
    size: tuple[float, float] | None,
    mesh: str | None,
    task: Any,
    rate_hz: float,
) -> Cloth | None:
    """
    Return the cloth a run of `task` simulates: `mesh`, else the grid; its start checked.

    The mesh is grasped nearest the grippers' start positions (in the recording's frame for a
    recorded motion, moved into the scene's as the grippers are). None: the engine's default
    grid. A mesh with a grid or a size is refused (it has its own).
    """
    task = as_task(task)
    cloth: Cloth | None
    if not mesh:
        cloth = cloth_grid(grid, size)
    elif grid or size is not None:
        raise InputError(
            f'cloth mesh {mesh}: a mesh has its own vertices and size; give no grid or cloth '
            'size with it'
        )
    else:
        cloth = read_cloth_mesh(mesh, *task_starts(task, rate_hz, size), task_placement(task))
    check_start(task, cloth, size)
    return cloth


def task_placement(task: Any) -> np.ndarray | None:
    """Return a recorded motion's 4x4 turn and translation into the scene (None: a task's own)."""
    if task.recorded is None:
        return None
    return np.asarray(task.recorded.to_scene, dtype=np.float64).reshape(4, 4)


def check_start(task: Any, cloth: Cloth | None, size: tuple[float, float] | None) -> None:
    """
    InputError, one line, if recorded grippers start further apart than the cloth allows.

    The cloth's allowance: a mesh's grasped vertices' distance, else the grid's grasped edge.
    """
    if task.recorded is None:
        return
    apart = float(np.linalg.norm(np.subtract(task.grasp[1], task.grasp[0])))
    if isinstance(cloth, ClothMesh):
        width = float(
            np.linalg.norm(cloth.rest[cloth.right_corner] - cloth.rest[cloth.left_corner])
        )
        allowed = f'its grasped vertices, {width:.3f} m apart in {cloth.source}'
    else:
        width = grasp_width(size) or CLOTH_WIDTH
        allowed = f'its grasped edge, {width:.3f} m, --cloth-size W,L'
    if apart > width + GRASP_SLACK:
        raise InputError(
            f'task {task.path}: the grippers start {apart:.3f} m apart, further than the '
            f'cloth ({allowed}) allows'
        )


def mesh_area(cloth: Cloth | None) -> float | None:
    """Return a mesh's area, which sets its mass (None for a grid: its size does)."""
    return cloth.area if isinstance(cloth, ClothMesh) else None


def mesh_record(cloth: Cloth | None) -> dict[str, Any]:
    """Return what a summary records of a `--cloth-mesh` ({} for a grid): no W x L size."""
    if not isinstance(cloth, ClothMesh):
        return {}
    return {'cloth_mesh': cloth.record(), 'cloth_size': None}


def cloth_faces(cloth: Cloth) -> np.ndarray:
    """Return the triangles the surface metrics are on, read-only (a mesh's or a grid's)."""
    faces = cloth.faces()
    faces.setflags(write=False)
    return faces


def task_starts(
    task: Any, rate_hz: float, size: tuple[float, float] | None
) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the grippers' start positions (left, right): the first targets of `task`.

    `task`: a Task, or a shipped task's name (core/task_data.py).
    """
    targets = full_targets(task, rate_hz, grasp_width(size))
    return targets.left[0], targets.right[0]
