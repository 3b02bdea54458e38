"""
MuJoCo cloth engine: a flex cloth held by two kinematic point grasps above a table.

Two cloth models, chosen by the `model` parameter:

- "shell" (the reference implementation's model; MuJoCo 3.1 used the shell plugin plus edge
  equality): a 2D flex whose edges are kept at their rest length by equality constraints
  (`edge_timeconst`), with MuJoCo's native shell bending (`elastic2d="bend"`: young, poisson,
  thickness) and passive edge damping. MuJoCo >= 3.3 refuses edge equality together with
  stretching elasticity, so the membrane is the edge constraint and the elasticity bends only.
  The constraint is soft: its stiffness is set in acceleration space (1 / timeconst^2), so in
  N/m it goes with the vertex mass, i.e. with the grid spacing squared. The same timeconst on a
  finer grid is a softer cloth (the towel hangs 17 mm longer at 46 x 64 than at 31 x 43); the
  same membrane on another grid needs `mesh_consistent_timeconst`, which `params_for_spacing`
  applies (with an internal step short enough for it) whenever a mesh is not the one the
  parameters were set for.
- "edges" (mass-spring): a net of springs on the grid, structural, shear (both diagonals) and
  bending (every second vertex), all of stiffness `edge_stiffness` and damping `damping`.
  MuJoCo >= 4.0 gives passive edge stiffness only to 1D flexes, so the net is a 1D flex whose
  elements are these springs (they collide as capsules of `radius`).

Grasp: each grasped corner vertex is made a heavy point (GRIPPER_MASS, weight cancelled) whose
position and velocity are prescribed every substep along the straight line from the previous
target to the new one, i.e. a kinematic point grasp without torque. MuJoCo's mocap attachments
are not available for flexes with elasticity, and a `connect` equality to a mocap body lags by
millimetres during the fling.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar, Mapping

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.engines.base import ClothEngine, EngineError, Instability, Param
import mujoco
import numpy as np

# MuJoCo reports an unstable state (NaN/Inf/huge qpos, qvel or qacc) as a warning and resets the
# data to the model's rest state; unhandled, it also writes MUJOCO_LOG.TXT into the working
# directory. The engine reads the warning counters instead (see `_step`), so the text is dropped.
mujoco.set_mju_user_warning(lambda text: None)
_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)

# Mass of each grasped corner, so that the cloth cannot move it within a substep.
GRIPPER_MASS = 1000.0  # kg

MODELS = ('shell', 'edges')
INTEGRATORS = ('Euler', 'discrete')
SOLVERS = ('Newton', 'CG', 'PGS')


# A scaled edge time constant this much under two internal steps is left to the engine's floor
# (a mesh whose x and z spacings round apart by ~1 % would otherwise double the substeps).
TIMECONST_SLACK = 0.01


def mesh_consistent_timeconst(timeconst: float, spacing_ratio: float) -> float:
    """
    Return the edge time constant that keeps a shell's membrane as stiff on another grid.

    `spacing_ratio` is the new grid spacing over the one `timeconst` was set for.
    """
    return timeconst * spacing_ratio


def spring_edges(grid: ClothGrid) -> np.ndarray:
    """Vertex pairs of a mass-spring cloth: structural, shear and bending springs, shape (m, 2)."""
    nx, nz = grid.nx, grid.nz
    index = np.arange(nx * nz).reshape(nz, nx)
    pairs = [
        (index[:, :-1], index[:, 1:]),  # structural, along x
        (index[:-1, :], index[1:, :]),  # structural, along z
        (index[:-1, :-1], index[1:, 1:]),  # shear
        (index[:-1, 1:], index[1:, :-1]),  # shear, other diagonal
        (index[:, :-2], index[:, 2:]),  # bending, along x
        (index[:-2, :], index[2:, :]),  # bending, along z
    ]
    return np.concatenate([np.stack([a.ravel(), b.ravel()], axis=1) for a, b in pairs])


class MujocoCloth(ClothEngine):
    """
    MuJoCo flex cloth: shell bending with inextensible edges, or a mass-spring net.

    reset(seed) starts the cloth in the task's seeded initial state (core/task.py) at rest.
    """

    name: ClassVar[str] = 'mujoco'
    instability_signals: ClassVar[tuple[str, ...]] = tuple(
        f'MuJoCo warning {w.name} (NaN, Inf or huge state; MuJoCo resets it)'
        for w in _INSTABILITY_WARNINGS
    )
    params: ClassVar[tuple[Param, ...]] = (
        Param(
            'model',
            'shell',
            '',
            doc='shell (bending + inextensible edges) or edges (mass-spring)',
            choices=MODELS,
        ),
        Param('mass', 0.5, 'kg', 1e-4, 100.0, 'mass of the whole cloth'),
        Param(
            'young', 30000.0, 'Pa', 0.0, 1e10, "Young's modulus of the shell bending (model shell)"
        ),
        Param('poisson', 0.45, '', 0.0, 0.499, 'Poisson ratio of the shell bending (model shell)'),
        Param(
            'thickness',
            0.001,
            'm',
            1e-5,
            0.05,
            'shell thickness; bending rigidity ~ young t^3 (model shell)',
        ),
        Param('damping', 0.05, 'N s/m', 0.0, 100.0, 'passive damping of every flex edge'),
        Param('edge_stiffness', 200.0, 'N/m', 0.0, 1e7, 'stiffness of every spring (model edges)'),
        Param(
            'edge_timeconst',
            0.01,
            's',
            1e-4,
            1.0,
            'time constant of the edge equality constraints (model shell), at least 2 internal'
            ' steps',
        ),
        Param('friction', 0.5, '', 0.0, 10.0, 'sliding friction coefficient of cloth contacts'),
        Param('radius', 0.004, 'm', 1e-4, 0.05, 'collision radius (half thickness) of the cloth'),
        Param(
            'timestep',
            0.002,
            's',
            1e-5,
            0.1,
            'longest internal step; substeps = ceil(dt / timestep)',
        ),
        Param('substeps', 1, '', 1, 10000, 'least number of internal steps per engine step'),
        Param(
            'solver_iterations', 50, '', 1, 10000, 'constraint solver iterations per internal step'
        ),
        Param(
            'solver',
            'Newton',
            '',
            doc=(
                'constraint solver: Newton (exact), CG (no factorisation; cheaper at a few '
                'iterations) or PGS'
            ),
            choices=SOLVERS,
        ),
        Param(
            'condim',
            3,
            '',
            1,
            3,
            'contact dimensionality: 3 (with friction) or 1 (frictionless, 4x fewer rows)',
        ),
        Param(
            'integrator',
            'Euler',
            '',
            doc='semi-implicit Euler (as in the paper) or discrete (implicit)',
            choices=INTEGRATORS,
        ),
        Param('self_collision', False, '', doc='cloth self-collision'),
    )

    @classmethod
    def version(cls) -> str:
        return mujoco.__version__

    @classmethod
    def params_for_spacing(
        cls, params: Mapping[str, Any], ratio: float, rate_hz: float
    ) -> dict[str, Any]:
        """
        Scale the shell's edge time constant with the spacing, the internal step if it must.

        The edge constraint's stiffness goes with the vertex mass (see the module docstring), so
        the same membrane needs `mesh_consistent_timeconst` of the time constant the cloth had
        (the engine floors it at two internal steps at `rate_hz`); where two internal steps
        exceed the scaled one (by more than TIMECONST_SLACK) the longest internal step becomes
        half of it, so a sweep's `timestep` on a finer mesh can be shortened.
        The mass-spring model's springs (N/m per edge) and every edge's damping describe a sheet
        of the same stiffness and damping on any grid: not scaled.
        """
        scaled = dict(params)
        config = cls.validate_params(params)
        if config['model'] == 'shell':
            dt = 1.0 / rate_hz
            substeps = max(int(config['substeps']), math.ceil(dt / config['timestep'] - 1e-9))
            # the time constant the cloth had: the engine floors it at two internal steps
            had = max(float(config['edge_timeconst']), 2 * dt / substeps)
            timeconst = mesh_consistent_timeconst(had, ratio)
            scaled['edge_timeconst'] = timeconst
            if 2 * dt / substeps > timeconst * (1 + TIMECONST_SLACK):
                scaled['timestep'] = timeconst / 2
        return scaled

    @classmethod
    def validate_params(cls, params: Mapping[str, Any]) -> dict[str, Any]:
        config = super().validate_params(params)
        if config['condim'] == 2:
            raise EngineError(
                'parameter condim must be 1 or 3 (MuJoCo has no 2-dimensional contact)'
            )
        if config['integrator'] == 'discrete':
            if config['model'] != 'shell':
                raise EngineError(
                    'parameter integrator=discrete needs model=shell (MuJoCo has no 1D edge'
                    ' springs there)'
                )
            if config['damping'] > 0:
                raise EngineError(
                    'parameter damping must be 0 with integrator=discrete (MuJoCo has no edge'
                    ' damping there)'
                )
        return config

    def __init__(
        self,
        rate_hz: float,
        params: Mapping[str, Any] | None = None,
        grid: ClothGrid | None = None,
    ) -> None:
        super().__init__(rate_hz, params, grid)
        try:
            self.model = mujoco.MjModel.from_xml_string(self._mjcf())
        except ValueError as exc:  # MuJoCo's compiler rejects a parameter combination
            raise EngineError(
                f'MuJoCo rejects the cloth parameters: {str(exc).splitlines()[0]}'
            ) from None
        self.data = mujoco.MjData(self.model)
        self._index_model()
        self._target = np.zeros((2, 3))  # gripper positions at the end of the last step
        self._goal = np.zeros((2, 3))
        self._velocity = np.zeros((2, 3))
        self._corner_q_now = np.zeros((2, 3))  # scratch: corner displacement at one substep

    # -- model --------------------------------------------------------------------------------

    def _mjcf(self) -> str:
        """Return the scene as MJCF: table and cloth (flexcomp with points in grid order)."""
        c = self.config
        x0, x1 = scene.TABLE_X
        y0, y1 = scene.TABLE_Y
        half = scene.TABLE_THICKNESS / 2
        friction = f'{c["friction"]:.9g} 0.005 0.0001'
        contact = (
            f'<contact selfcollide="{"auto" if c["self_collision"] else "none"}"'
            f' friction="{friction}" condim="{c["condim"]}" solref="{max(2 * self.h, 0.005):.9g}'
            ' 1" solimp="0.95 0.99 0.001"/>'
        )
        points = ' '.join(f'{v:.12g}' for v in self._rest.ravel())
        if c['model'] == 'shell':
            elements = self.grid.faces()
            material = (
                f'<edge equality="true" solref="{max(c["edge_timeconst"], 2 * self.h):.9g} 1" '
                f'damping="{c["damping"]:.9g}"/>\n'
                f'      <elasticity young="{c["young"]:.9g}" poisson="{c["poisson"]:.9g}" '
                f'thickness="{c["thickness"]:.9g}" elastic2d="bend"/>'
            )
            dim = 2
        else:
            elements = spring_edges(self.grid)
            material = (
                f'<edge stiffness="{c["edge_stiffness"]:.9g}" damping="{c["damping"]:.9g}"/>'
            )
            dim = 1
        element = ' '.join(str(int(i)) for i in elements.ravel())
        return f"""
<mujoco model="cloth_bench_{c['model']}">
  <option timestep="{self.h:.12g}" gravity="0 0 {scene.GRAVITY}" integrator="{c['integrator']}"
          solver="{c['solver']}" iterations="{c['solver_iterations']}"/>
  <worldbody>
    <geom name="table" type="box" friction="{friction}" condim="{c['condim']}"
          size="{(x1 - x0) / 2} {(y1 - y0) / 2} {half}"
          pos="{(x0 + x1) / 2} {(y0 + y1) / 2} {scene.TABLE_TOP_Z - half}"/>
    <flexcomp name="cloth" type="direct" dim="{dim}" point="{points}" element="{element}"
              mass="{c['mass']:.9g}" radius="{c['radius']:.9g}">
      {contact}
      {material}
    </flexcomp>
  </worldbody>
</mujoco>"""

    def _index_model(self) -> None:
        """Map grid vertices to their slide joints (order checked); make the corners kinematic."""
        m, d = self.model, self.data
        mujoco.mj_forward(m, d)
        n = len(self._rest)
        if not np.allclose(d.flexvert_xpos[:n], self._rest, atol=1e-9):
            raise RuntimeError('MuJoCo flex vertex order differs from the grid order')
        bodies = m.flex_vertbodyid[:n]
        joints = m.body_jntadr[bodies][:, None] + np.arange(3)
        if not (
            np.all(m.body_jntnum[bodies] == 3) and np.allclose(m.jnt_axis[joints], np.eye(3)[None])
        ):
            raise RuntimeError('MuJoCo flex vertices are not point masses on world x, y, z slides')
        self._qadr = m.jnt_qposadr[joints]  # (n, 3): qpos = displacement from the rest grid
        first = int(self._qadr[0, 0])
        contiguous = np.array_equal(self._qadr.ravel(), np.arange(first, first + 3 * n))
        self._qpos_slice = (
            slice(first, first + 3 * n) if contiguous else None
        )  # read as a view, no gather
        self._corner_q = self._qadr[self._corners]
        self._corner_dof = m.jnt_dofadr[joints[self._corners]]
        self._corner_rest = self._rest[self._corners]
        for b in bodies[self._corners]:
            m.body_mass[b] = GRIPPER_MASS
            m.body_inertia[b] = GRIPPER_MASS * 1e-4
        mujoco.mj_setConst(m, d)
        self._weight_cancel = np.zeros(m.nv)
        self._weight_cancel[self._corner_dof[:, 2]] = -GRIPPER_MASS * scene.GRAVITY

    def _vertices_now(self) -> np.ndarray:
        """Vertex positions from qpos (mjData.flexvert_xpos lags one substep after mj_step)."""
        if self._qpos_slice is not None:
            return np.add(self._rest, self.data.qpos[self._qpos_slice].reshape(self._rest.shape))
        return self._rest + self.data.qpos[self._qadr]

    # -- ClothEngine --------------------------------------------------------------------------

    def _reset(self, displacement: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self._qadr] = displacement
        d.qfrc_applied[:] = self._weight_cancel
        self._target[0], self._target[1] = left, right
        mujoco.mj_forward(m, d)
        return self._vertices_now()

    def _step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        m, d = self.model, self.data
        self._goal[0], self._goal[1] = left, right
        np.subtract(self._goal, self._target, out=self._velocity)
        self._velocity /= self.dt
        corner = self._corner_q_now
        for k in range(self.substeps):
            np.multiply(self._velocity, k * self.h, out=corner)  # target + k h v - rest, in place
            np.add(self._target, corner, out=corner)
            np.subtract(corner, self._corner_rest, out=corner)
            d.qpos[self._corner_q] = corner
            d.qvel[self._corner_dof] = self._velocity
            mujoco.mj_step(m, d)
        # The counters only grow, so one look after the substeps sees a warning of any of them.
        for w in _INSTABILITY_WARNINGS:
            if d.warning[w].number:
                # MuJoCo has already reset the state: report it rather than return the reset.
                raise Instability(f'MuJoCo {w.name}: the state went NaN, Inf or huge')
        self._target[:] = self._goal
        return self._vertices_now()

    def close(self) -> None:
        self.data = None  # type: ignore[assignment]
        self.model = None  # type: ignore[assignment]
