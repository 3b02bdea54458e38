"""
PyBullet cloth engine: a deformable-world soft body held by two kinematic point grasps.

Two cloth models, chosen by the `model` parameter:

- "mass_spring" (the reference implementation's model): the grid's triangles loaded as a soft
  body with structural springs (`elastic`, `damping`) and bending springs (`bending`).
- "neo_hookean" (FEM): Bullet's Neo-Hookean force acts on tetrahedra only, so the cloth is a
  slab of `fem_thickness` made of two layers of the grid, each cell split into six tetrahedra
  (a `--cloth-mesh`: two layers along the vertex normals, three tetrahedra per triangle); a cloth
  vertex is the midpoint of its two layer nodes.

Each engine owns a DIRECT physics client (no GUI, no rendering), so that several engines can
live in one process. A grasped corner is anchored to a massless (kinematic) body that is moved
every substep along the straight line from the previous target to the new one.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as package_version
from pathlib import Path
import tempfile
from typing import Any, ClassVar, Mapping

from cloth_bench_ros.engines.quiet import quiet_c_output
import numpy as np

with quiet_c_output():  # pybullet prints its build time on import
    import pybullet as pb

from cloth_bench_ros.core import scene  # noqa: I100  (after pybullet's quiet import)
from cloth_bench_ros.core.cloth_mesh import Cloth, ClothMesh
from cloth_bench_ros.engines.base import ClothEngine, Param

MODELS = ('mass_spring', 'neo_hookean')
_IDENTITY = (0.0, 0.0, 0.0, 1.0)


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Write a triangle mesh as Wavefront OBJ (1-based face indices)."""
    lines = [f'v {x:.9f} {y:.9f} {z:.9f}' for x, y, z in vertices]
    lines += [f'f {a + 1} {b + 1} {c + 1}' for a, b, c in faces]
    path.write_text('\n'.join(lines) + '\n')


def slab_tetrahedra(grid: Cloth, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """
    Return the cloth as a slab: nodes (2n, 3) and positively oriented tetrahedra.

    Layer 0 is at y = -t/2, then layer 1 at +t/2; 6 tetrahedra per grid cell (Kuhn split,
    conforming across cells). A mesh's layers are half the thickness either side along each
    vertex's normal, 3 tetrahedra per triangle (`prism_tetrahedra`).
    """
    if isinstance(grid, ClothMesh) and grid.grid is not None:  # a grid's own slab
        return slab_tetrahedra(grid.grid, thickness)
    rest = grid.vertices()
    n = len(rest)
    if isinstance(grid, ClothMesh):
        import trimesh  # lazy: +0.6 s at an engine's start, not in .venv-ros; meshes only

        normals = trimesh.Trimesh(rest, grid.faces(), process=False).vertex_normals
        nodes = np.concatenate([rest - normals * thickness / 2, rest + normals * thickness / 2])
        return nodes, prism_tetrahedra(nodes, grid.faces())
    half = np.array([0.0, thickness / 2, 0.0])
    nodes = np.concatenate([rest - half, rest + half])
    tets = []
    for j in range(grid.nz - 1):
        for i in range(grid.nx - 1):

            def corner(bits: tuple[int, int, int]) -> int:
                dx, dz, layer = bits
                return layer * n + (j + dz) * grid.nx + (i + dx)

            for a, b, _ in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
                path = [[0, 0, 0]]
                for axis in (a, b):
                    step = list(path[-1])
                    step[axis] = 1
                    path.append(step)
                path.append([1, 1, 1])
                tet = [corner((p[0], p[1], p[2])) for p in path]
                p0, p1, p2, p3 = nodes[tet]
                if np.dot(np.cross(p1 - p0, p2 - p0), p3 - p0) < 0:
                    tet[1], tet[2] = tet[2], tet[1]
                tets.append(tet)
    return nodes, np.asarray(tets, dtype=np.int64)


def prism_tetrahedra(nodes: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """
    Return 3 positively oriented tetrahedra per triangle's prism between the two layers.

    With a triangle's vertices sorted (a < b < c), each side of the prism is cut along the
    diagonal from its lower-numbered bottom vertex to the other's top, so neighbours conform.
    """
    n = len(nodes) // 2
    a, b, c = np.sort(faces, axis=1).T
    tets = np.concatenate([
        np.stack([a, b, c, c + n], axis=1),
        np.stack([a, b, b + n, c + n], axis=1),
        np.stack([a, a + n, b + n, c + n], axis=1),
    ])
    p0, p1, p2, p3 = (nodes[tets[:, k]] for k in range(4))
    flip = np.einsum('ij,ij->i', np.cross(p1 - p0, p2 - p0), p3 - p0) < 0
    tets[flip, 1], tets[flip, 2] = tets[flip, 2], tets[flip, 1].copy()
    return tets


def write_vtk(path: Path, nodes: np.ndarray, tets: np.ndarray) -> None:
    """Write a tetrahedral mesh as legacy ASCII VTK (unstructured grid), as Bullet loads it."""
    lines = [
        '# vtk DataFile Version 2.0',
        'cloth slab',
        'ASCII',
        'DATASET UNSTRUCTURED_GRID',
        f'POINTS {len(nodes)} double',
    ]
    lines += [f'{x:.9f} {y:.9f} {z:.9f}' for x, y, z in nodes]
    lines.append(f'CELLS {len(tets)} {5 * len(tets)}')
    lines += [f'4 {a} {b} {c} {d}' for a, b, c, d in tets]
    lines.append(f'CELL_TYPES {len(tets)}')
    lines += ['10'] * len(tets)
    path.write_text('\n'.join(lines) + '\n')


def match_nodes(loaded: np.ndarray, wanted: np.ndarray, tolerance: float = 1e-5) -> np.ndarray:
    """Return the index into `loaded` of each `wanted` node; RuntimeError if one is missing."""
    d2 = ((wanted[:, None, :] - loaded[None, :, :]) ** 2).sum(axis=2)
    index = d2.argmin(axis=1)
    if np.sqrt(d2[np.arange(len(wanted)), index]).max() > tolerance or len(set(index)) != len(
        index
    ):
        raise RuntimeError('PyBullet soft-body nodes do not match the cloth mesh')
    return index


class BulletCloth(ClothEngine):
    """
    PyBullet deformable cloth: mass-spring with bending springs, or Neo-Hookean FEM slab.

    reset(seed) rebuilds the world (so one seed always gives bit-identical runs) and places the
    cloth in the task's seeded initial state (core/task.py); both layers of a FEM slab move
    together.
    """

    name: ClassVar[str] = 'bullet'
    # PyBullet reports no instability of its own: a blown-up cloth shows in the state checks.
    instability_signals: ClassVar[tuple[str, ...]] = ()
    # Near the towel's optimum a 6 x 8 mesh ranks trials as 11 x 15 does (Spearman 0.90 over 30),
    # a 3 x 4 one does not (0.61): the springs of a 12-node sheet are another cloth. With one rung
    # `coarse` fits the fling within 6.3 % of `full` (was 35.5 % with two).
    screen_halvings: ClassVar[int] = 1
    params: ClassVar[tuple[Param, ...]] = (
        Param(
            'model',
            'mass_spring',
            '',
            doc='mass_spring (with bending springs) or neo_hookean (FEM slab)',
            choices=MODELS,
        ),
        Param('mass', 0.5, 'kg', 1e-4, 100.0, 'mass of the whole cloth'),
        Param('elastic', 10.0, 'N/m', 0.0, 1e6, 'spring elastic stiffness (mass_spring)'),
        Param('damping', 0.05, 'N s/m', 0.0, 100.0, 'spring damping stiffness (mass_spring)'),
        Param('bending', 30.0, 'N/m', 0.0, 1e6, 'bending spring stiffness (mass_spring)'),
        Param('bending_springs', True, '', doc='add bending springs (mass_spring)'),
        Param('neohookean_mu', 20000.0, 'Pa', 0.0, 1e9, 'Neo-Hookean shear modulus (neo_hookean)'),
        Param(
            'neohookean_lambda',
            40000.0,
            'Pa',
            0.0,
            1e9,
            'Neo-Hookean first Lame parameter (neo_hookean)',
        ),
        Param('neohookean_damping', 0.01, 's', 0.0, 10.0, 'Neo-Hookean damping (neo_hookean)'),
        Param(
            'fem_thickness',
            0.005,
            'm',
            1e-4,
            0.05,
            'slab thickness of the FEM cloth (neo_hookean)',
        ),
        Param('friction', 0.5, '', 0.0, 20.0, 'soft-body friction coefficient'),
        Param('collision_margin', 0.004, 'm', 1e-4, 0.05, 'soft-body collision margin'),
        Param(
            'timestep',
            0.0025,
            's',
            1e-5,
            0.1,
            'longest internal step; substeps = ceil(dt / timestep); neo_hookean needs <= 0.001 for'
            ' the fling',
        ),
        Param('substeps', 1, '', 1, 10000, 'least number of internal steps per engine step'),
        Param('solver_iterations', 50, '', 1, 10000, 'solver iterations per internal step'),
        Param('self_collision', False, '', doc='cloth self-collision'),
    )

    @classmethod
    def version(cls) -> str:
        try:
            return package_version('pybullet')
        except PackageNotFoundError:
            return str(pb.getAPIVersion())

    def __init__(
        self,
        rate_hz: float,
        params: Mapping[str, Any] | None = None,
        grid: Cloth | None = None,
    ) -> None:
        super().__init__(rate_hz, params, grid)
        c = self.config
        self._fem = c['model'] == 'neo_hookean'
        self._tmp = tempfile.TemporaryDirectory(prefix='cloth_bench_bullet_')
        if self._fem:
            self._nodes_rest, tets = slab_tetrahedra(self.grid, float(c['fem_thickness']))
            self._mesh = Path(self._tmp.name) / 'cloth.vtk'
            write_vtk(self._mesh, self._nodes_rest, tets)
        else:
            self._nodes_rest = self._rest
            self._mesh = Path(self._tmp.name) / 'cloth.obj'
            write_obj(self._mesh, self._rest, self.grid.faces())
        self._layers = 2 if self._fem else 1
        self._client = pb.connect(pb.DIRECT)
        if self._client < 0:
            raise RuntimeError('PyBullet could not start a DIRECT physics client')
        self._target = np.zeros((2, 3))
        self._cloth = -1
        self._grippers: list[int] = []
        self._order = np.arange(len(self._nodes_rest))

    # -- world --------------------------------------------------------------------------------

    def _build(self) -> None:
        """Build a fresh deformable world: gravity, table, cloth, kinematic grippers, anchors."""
        c, cid = self.config, self._client
        pb.resetSimulation(pb.RESET_USE_DEFORMABLE_WORLD, physicsClientId=cid)
        pb.setGravity(0.0, 0.0, scene.GRAVITY, physicsClientId=cid)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=self.h,
            numSubSteps=0,
            numSolverIterations=int(c['solver_iterations']),
            physicsClientId=cid,
        )
        x0, x1 = scene.TABLE_X
        y0, y1 = scene.TABLE_Y
        half = scene.TABLE_THICKNESS / 2
        box = pb.createCollisionShape(
            pb.GEOM_BOX, halfExtents=[(x1 - x0) / 2, (y1 - y0) / 2, half], physicsClientId=cid
        )
        table = pb.createMultiBody(
            0.0,
            box,
            -1,
            [(x0 + x1) / 2, (y0 + y1) / 2, scene.TABLE_TOP_Z - half],
            physicsClientId=cid,
        )
        pb.changeDynamics(table, -1, lateralFriction=1.0, physicsClientId=cid)
        common = {
            'basePosition': [0.0, 0.0, 0.0],
            'baseOrientation': list(_IDENTITY),
            'scale': 1.0,
            'mass': float(c['mass']),
            'collisionMargin': float(c['collision_margin']),
            'frictionCoeff': float(c['friction']),
            'useSelfCollision': int(c['self_collision']),
            'useFaceContact': 1,
            'physicsClientId': cid,
        }
        with quiet_c_output():
            self._cloth = self._load_cloth(common)
        if self._cloth < 0:
            raise RuntimeError(f'PyBullet could not load the cloth mesh {self._mesh}')
        self._order = match_nodes(self._mesh_nodes(), self._nodes_rest)
        n = len(self._rest)
        self._grippers = []
        for corner in self._corners:
            body = pb.createMultiBody(
                0.0, -1, -1, self._rest[corner].tolist(), physicsClientId=cid
            )
            for layer in range(self._layers):
                node = layer * n + corner
                offset = self._nodes_rest[node] - self._rest[corner]
                pb.createSoftBodyAnchor(
                    self._cloth,
                    int(self._order[node]),
                    body,
                    -1,
                    offset.tolist(),
                    physicsClientId=cid,
                )
            self._grippers.append(body)

    def _load_cloth(self, common: dict) -> int:
        """Load the cloth mesh as a soft body of the chosen model; its body id (< 0 on failure)."""
        c = self.config
        if self._fem:
            return pb.loadSoftBody(
                str(self._mesh),
                useNeoHookean=1,
                useMassSpring=0,
                useBendingSprings=0,
                NeoHookeanMu=float(c['neohookean_mu']),
                NeoHookeanLambda=float(c['neohookean_lambda']),
                NeoHookeanDamping=float(c['neohookean_damping']),
                **common,
            )
        return pb.loadSoftBody(
            str(self._mesh),
            useNeoHookean=0,
            useMassSpring=1,
            useBendingSprings=int(c['bending_springs']),
            springElasticStiffness=float(c['elastic']),
            springDampingStiffness=float(c['damping']),
            springBendingStiffness=float(c['bending']),
            **common,
        )

    def _mesh_nodes(self) -> np.ndarray:
        """Soft-body node positions in PyBullet's order, (m, 3)."""
        _, nodes = pb.getMeshData(
            self._cloth, -1, flags=pb.MESH_DATA_SIMULATION_MESH, physicsClientId=self._client
        )
        return np.asarray(nodes, dtype=float)

    def _vertices_now(self) -> np.ndarray:
        nodes = self._mesh_nodes()[self._order]
        if self._fem:
            n = len(self._rest)
            return 0.5 * (nodes[:n] + nodes[n:])
        return nodes

    def _move_grippers(self, positions: np.ndarray) -> None:
        for body, xyz in zip(self._grippers, positions):
            pb.resetBasePositionAndOrientation(
                body, xyz.tolist(), _IDENTITY, physicsClientId=self._client
            )

    # -- ClothEngine --------------------------------------------------------------------------

    def _reset(self, displacement: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        self._build()
        nodes = np.empty_like(self._nodes_rest)
        nodes[self._order] = self._nodes_rest + np.tile(displacement, (self._layers, 1))
        pb.resetMeshData(self._cloth, vertices=nodes.tolist(), physicsClientId=self._client)
        self._target[0], self._target[1] = left, right
        self._move_grippers(self._target)
        return self._vertices_now()

    def _step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        goal = np.stack([left, right])
        for k in range(1, self.substeps + 1):
            self._move_grippers(self._target + (k / self.substeps) * (goal - self._target))
            pb.stepSimulation(physicsClientId=self._client)
        self._target[:] = goal
        return self._vertices_now()

    def close(self) -> None:
        if self._client >= 0 and pb.isConnected(physicsClientId=self._client):
            pb.disconnect(physicsClientId=self._client)
        self._client = -1
        self._tmp.cleanup()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass
