"""
Newton cloth engine (NVIDIA Warp, on the CPU or a CUDA device): XPBD or VBD cloth, two grasps.

Two cloth models, chosen by the `model` parameter:

- "xpbd" (position-based dynamics, the class of NVIDIA Flex in the paper): extended PBD with
  distance springs on every mesh edge and across every pair of adjacent triangles (structural,
  shear and bending springs of stiffness `spring_stiffness`) plus dihedral-angle bending
  constraints (`bending`), solved by SolverXPBD.
- "vbd" (vertex block descent, implicit Euler with Neo-Hookean-like triangle elements, close to
  SOFA's FEM in the paper): membrane stiffness `tri_stiffness` (shear, Lame mu),
  `tri_area_stiffness` (Lame lambda), dihedral bending `bending`, solved by SolverVBD.

Grasp: each grasped corner is a kinematic particle (mass 0, not ACTIVE): Newton's solvers leave
its position alone, so it is written before every substep at the point of the straight line from
the previous target to the new one reached at the end of that substep, with the line's velocity.
The table is a static box shape. With `graph_capture`, one engine step (all substeps) is recorded
once as a Warp graph and replayed; the targets are read from device arrays by a small kernel.

Device: `device` (`--device` on every command) is `cpu`, `cuda`, `cuda:N` or `auto` (the default:
the first CUDA device if Warp finds one, else the CPU); a device that is not on the machine is
refused by `validate_params`, before anything runs. The device changes the numbers (float32
kernels in another order), so a run names its device. `deterministic` is Warp's deterministic
mode for the solvers' atomics (and Newton's sorted contacts): `run_to_run` makes a CUDA run give
the same numbers every time, `gpu_to_gpu` on every GPU architecture; on the CPU, which runs the
kernels in order, it changes no number (docs/engines.md, "Deterministic atomics").

Warp compiles its kernels on first use (about 35 s per solver on one core) and caches them in its
kernel cache (by default ~/.cache/warp); `cloth-bench engines --warm` fills it.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as package_version
from typing import Any, ClassVar, Mapping

from cloth_bench_ros.engines.quiet import quiet_c_output
import numpy as np
import warp as wp

wp.config.log_level = wp.LOG_ERROR  # no banner and no line per compiled module
with quiet_c_output():  # Warp's C++ init warns on stderr that there is no CUDA driver
    wp.init()
from cloth_bench_ros import validation  # noqa: E402, I100  (after Warp's quiet init)
from cloth_bench_ros.core import scene  # noqa: E402
from cloth_bench_ros.core.scene import ClothGrid  # noqa: E402
from cloth_bench_ros.engines.base import ClothEngine, EngineError, Param  # noqa: E402
import newton  # noqa: E402

MODELS = ('xpbd', 'vbd')
DETERMINISTIC = {  # the `deterministic` parameter's values: Warp's modes
    'off': wp.DeterministicMode.NOT_GUARANTEED,
    'run_to_run': wp.DeterministicMode.RUN_TO_RUN,
    'gpu_to_gpu': wp.DeterministicMode.GPU_TO_GPU,
}


def available_devices() -> tuple[str, ...]:
    """Return the devices Warp finds on this machine: `cpu`, then `cuda:0`, `cuda:1`, ..."""
    return ('cpu', *(f'cuda:{i}' for i in range(wp.get_cuda_device_count())))


def resolve_device(name: str) -> str:
    """
    Return the Warp device `name` means here (`auto`: the first CUDA device, else `cpu`).

    EngineError, one line naming what Warp found, for a device that is not on this machine.
    """
    found = available_devices()
    if name == 'auto':
        return found[1] if len(found) > 1 else 'cpu'
    wanted = 'cuda:0' if name == 'cuda' else name
    if wanted not in found:
        raise EngineError(
            f'parameter device: {name} is not on this machine (Warp found: {", ".join(found)})'
        )
    return wanted


@wp.kernel
def _move_grasps(
    start: wp.array(dtype=wp.vec3),
    velocity: wp.array(dtype=wp.vec3),
    index: wp.array(dtype=wp.int32),
    t: float,
    q: wp.array(dtype=wp.vec3),
    qd: wp.array(dtype=wp.vec3),
):
    """Kinematic corner i at start[i] + t * velocity[i], moving with velocity[i]."""
    i = wp.tid()
    q[index[i]] = start[i] + t * velocity[i]
    qd[index[i]] = velocity[i]


class NewtonCloth(ClothEngine):
    """
    Newton cloth: XPBD springs and bending, or VBD triangle elements and bending, on a device.

    reset(seed) starts the cloth in the task's seeded initial state (core/task.py) at rest.
    """

    name: ClassVar[str] = 'newton'
    # Newton and Warp report no instability of their own: a blown-up cloth's particle state goes
    # non-finite or out of bounds, which the state checks see.
    instability_signals: ClassVar[tuple[str, ...]] = ()
    params: ClassVar[tuple[Param, ...]] = (
        Param(
            'model',
            'xpbd',
            '',
            doc='xpbd (springs + bending, Flex class) or vbd (triangle FEM, SOFA class)',
            choices=MODELS,
        ),
        Param(
            'mass',
            0.5,
            'kg',
            1e-4,
            100.0,
            'mass of the whole cloth, spread by area over the free (not grasped) vertices',
        ),
        Param(
            'spring_stiffness',
            100.0,
            'N/m',
            0.0,
            1e7,
            'stiffness of the structural, shear and bending springs (model xpbd); too stiff for'
            ' the particle mass and substep diverges (1000 did at 11x15 and 2 ms)',
        ),
        Param(
            'spring_damping',
            0.01,
            'N s/m',
            0.0,
            1e4,
            'damping of the springs (model xpbd); 0.1 at 0.5 kg already crumples the cloth (Jacobi'
            ' solve)',
        ),
        Param(
            'tri_stiffness',
            1000.0,
            'N/m',
            0.0,
            1e7,
            'membrane shear stiffness of the Neo-Hookean triangles, Lame mu x thickness (model'
            ' vbd)',
        ),
        Param(
            'tri_area_stiffness',
            1000.0,
            'N/m',
            0.0,
            1e7,
            'membrane area stiffness of the Neo-Hookean triangles, Lame lambda x thickness (model'
            ' vbd)',
        ),
        Param(
            'tri_damping',
            0.01,
            'N s/m',
            0.0,
            100.0,
            "damping of the triangles' strain rate (Newton tri_kd; model vbd)",
        ),
        Param(
            'bending',
            6e-5,
            'N m',
            0.0,
            1.0,
            'flexural rigidity D of the cloth, turned into dihedral-edge stiffness for the grid'
            ' spacing',
        ),
        Param(
            'bending_damping',
            0.0,
            'N m s',
            0.0,
            10.0,
            'damping of the dihedral angles (Newton edge_kd)',
        ),
        Param('friction', 0.5, '', 0.0, 10.0, 'friction coefficient of cloth-table contacts'),
        Param(
            'particle_radius',
            0.004,
            'm',
            1e-4,
            0.05,
            'collision radius (half thickness) of the cloth',
        ),
        Param(
            'contact_stiffness',
            1000.0,
            'N/m',
            1.0,
            1e7,
            'cloth-table contact stiffness (model vbd)',
        ),
        Param(
            'contact_damping', 0.01, 'N s/m', 0.0, 1e4, 'cloth-table contact damping (model vbd)'
        ),
        Param(
            'timestep',
            0.002,
            's',
            1e-5,
            0.1,
            'longest internal step; substeps = ceil(dt / timestep)',
        ),
        Param('substeps', 1, '', 1, 10000, 'least number of internal steps per engine step'),
        Param('solver_iterations', 10, '', 1, 1000, 'solver iterations per internal step'),
        Param(
            'self_collision',
            False,
            '',
            doc=(
                'cloth self-collision (particle spheres for xpbd, '
                'vertex-triangle and edge-edge for vbd)'
            ),
        ),
        Param('graph_capture', True, '', doc='record one step as a Warp graph and replay it'),
        Param(
            'device',
            'auto',
            '',
            doc='cpu, cuda, cuda:N, or auto (the first CUDA device Warp finds, else cpu)',
            check=validation.device,
        ),
        Param(
            'deterministic',
            'off',
            '',
            doc="Warp's deterministic atomics on CUDA: off, run_to_run (the same numbers every run"
            ' on one GPU) or gpu_to_gpu (on every GPU architecture)',
            choices=tuple(DETERMINISTIC),
        ),
    )

    @classmethod
    def validate_params(cls, params: Mapping[str, Any]) -> dict[str, Any]:
        config = super().validate_params(params)
        resolve_device(str(config['device']))  # refused here, before anything runs
        return config

    @classmethod
    def device_for(cls, params: Mapping[str, Any]) -> str:
        return resolve_device(str(cls.validate_params(params)['device']))

    @classmethod
    def devices(cls) -> tuple[str, ...]:
        return available_devices()

    @classmethod
    def version(cls) -> str:
        try:
            return f'{package_version("newton")} (warp {wp.config.version})'
        except PackageNotFoundError:
            return f'unknown (warp {wp.config.version})'

    @classmethod
    def params_for_spacing(
        cls, params: Mapping[str, Any], ratio: float, rate_hz: float
    ) -> dict[str, Any]:
        """
        Scale the table contact with the vertex area, and XPBD's internal step on finer meshes.

        Contact stiffness and damping are per vertex, whose weight goes with its area. XPBD's
        springs (per edge) make the same sheet on any grid, but a spring's time constant
        sqrt(m / k) goes with the spacing (at 21 x 29 the preset's 2 ms diverges). VBD is
        implicit; membrane (per area) and bending (`_edge_stiffness`) need nothing.
        """
        scaled = dict(params)
        config = cls.validate_params(params)
        for name in ('contact_stiffness', 'contact_damping'):
            scaled[name] = float(config[name]) * ratio**2
        if config['model'] == 'xpbd' and ratio < 1:
            scaled['timestep'] = float(config['timestep']) * ratio
        return scaled

    @classmethod
    def warm(cls) -> None:
        """Compile every kernel of both models (self-collision or not) on every device here."""
        grid = ClothGrid(3, 3)
        left, right = grid.vertices()[grid.left_corner], grid.vertices()[grid.right_corner]
        for device in available_devices():  # Warp compiles for each: CPU code, then CUDA code
            for model in MODELS:
                for self_collision in (False, True):
                    engine = cls(100.0, {'model': model, 'self_collision': self_collision,
                                         'device': device}, grid)
                    engine.reset(0, left, right)
                    engine.step(left, right)
                    engine.close()

    def __init__(
        self,
        rate_hz: float,
        params: Mapping[str, Any] | None = None,
        grid: ClothGrid | None = None,
    ) -> None:
        super().__init__(rate_hz, params, grid)
        c = self.config
        self._vbd = c['model'] == 'vbd'
        self.device = resolve_device(str(c['device']))
        with wp.ScopedDevice(self.device):
            self.model = self._build_model()
            self._states = (self.model.state(), self.model.state())
            self._control = self.model.control()
            self._pipeline = newton.CollisionPipeline(
                self.model, deterministic=c['deterministic'] != 'off'
            )
            self._contacts = self._pipeline.contacts()
            self.solver = self._make_solver()
            self._start = wp.zeros(2, dtype=wp.vec3)
            self._velocity = wp.zeros(2, dtype=wp.vec3)
            self._index = wp.array(self._corners, dtype=wp.int32)
        self._target = np.zeros((2, 3))
        self._graph = None

    # -- model --------------------------------------------------------------------------------

    def _build_model(self, finalize: bool = True) -> Any:
        """Table box, cloth mesh in grid order, corner particles kinematic (or the builder)."""
        c = self.config
        builder = newton.ModelBuilder(gravity=(0.0, 0.0, scene.GRAVITY))
        x0, x1 = scene.TABLE_X
        y0, y1 = scene.TABLE_Y
        half = scene.TABLE_THICKNESS / 2
        table = newton.ModelBuilder.ShapeConfig(
            mu=float(c['friction']),
            ke=float(c['contact_stiffness']),
            kd=float(c['contact_damping']),
        )
        builder.add_shape_box(
            -1,
            xform=wp.transform(
                wp.vec3((x0 + x1) / 2, (y0 + y1) / 2, scene.TABLE_TOP_Z - half), wp.quat_identity()
            ),
            hx=(x1 - x0) / 2,
            hy=(y1 - y0) / 2,
            hz=half,
            cfg=table,
            label='table',
        )
        area = self.grid.width * self.grid.length
        xpbd = not self._vbd
        builder.add_cloth_mesh(
            pos=wp.vec3(0.0, 0.0, 0.0),
            rot=wp.quat_identity(),
            scale=1.0,
            vel=wp.vec3(0.0, 0.0, 0.0),
            vertices=[wp.vec3(*v) for v in self._rest],
            indices=self.grid.faces().ravel().tolist(),
            density=float(c['mass']) / area,
            tri_ke=0.0 if xpbd else float(c['tri_stiffness']),
            tri_ka=0.0 if xpbd else float(c['tri_area_stiffness']),
            tri_kd=0.0 if xpbd else float(c['tri_damping']),
            edge_ke=self._edge_stiffness(),
            edge_kd=float(c['bending_damping']),
            add_springs=xpbd,
            spring_ke=float(c['spring_stiffness']),
            spring_kd=float(c['spring_damping']),
            particle_radius=float(c['particle_radius']),
        )
        for corner in self._corners:
            builder.particle_mass[corner] = 0.0
            builder.particle_flags[corner] = int(builder.particle_flags[corner]) & ~int(
                newton.ParticleFlags.ACTIVE
            )
        free = sum(builder.particle_mass)  # the free particles carry the whole mass
        builder.particle_mass = [m * float(c['mass']) / free for m in builder.particle_mass]
        if self._vbd:
            builder.color(include_bending=True)
        if not finalize:  # one world of several (benchmarks/bench_vectorised_worlds.py)
            return builder
        model = builder.finalize()
        model.soft_contact_ke = float(c['contact_stiffness'])
        model.soft_contact_kd = float(c['contact_damping'])
        model.soft_contact_mu = float(c['friction'])
        if xpbd and not c['self_collision']:
            # SolverXPBD solves particle-particle contacts whenever the largest radius is positive;
            # particle-shape contacts read the per-particle radii, not this maximum.
            model.particle_max_radius = 0.0
            model.particle_grid = None
        return model

    def _edge_stiffness(self) -> float:
        """
        Newton's per-edge bending stiffness that gives the cloth the flexural rigidity `bending`.

        On a grid of spacing a (right triangles), a plate bent to curvature k has dihedral angles
        k 2a/3 across the straight edges and (k/2) a sqrt(2)/3 across the diagonals; VBD's energy
        1/2 ke |e| theta^2 per edge then sums to 1/2 (0.523 ke a) k^2 per area, so ke = 1.91 D / a.
        XPBD's bending constraint has no |e| factor (energy 1/2 ke theta^2), hence ke = 1.91 D.
        """
        dx, dz = self.grid.spacing
        a = float(np.sqrt(dx * dz))
        per_length = 1.91 * float(self.config['bending']) / a
        return per_length if self._vbd else per_length * a

    def _make_solver(self):
        c = self.config
        if self._vbd:
            radius = float(c['particle_radius'])
            return newton.solvers.SolverVBD(
                self.model,
                iterations=int(c['solver_iterations']),
                particle_enable_self_contact=bool(c['self_collision']),
                particle_self_contact_margin=2 * radius,  # two cloth layers touch
                particle_self_contact_gap=2 * radius,
                deterministic=DETERMINISTIC[c['deterministic']],
            )
        return newton.solvers.SolverXPBD(
            self.model,
            iterations=int(c['solver_iterations']),
            deterministic=DETERMINISTIC[c['deterministic']],
        )

    # -- stepping -----------------------------------------------------------------------------

    def _substeps(self, move: Any = _move_grasps, grasps: int = 2) -> None:
        """All substeps of one step (`grasps` corners moved by `move`); ends in _states[0]."""
        a, b = self._states
        for k in range(1, self.substeps + 1):
            for s in (a, b):
                wp.launch(
                    move,
                    dim=grasps,
                    inputs=[self._start, self._velocity, self._index, k * self.h],
                    outputs=[s.particle_q, s.particle_qd],
                    device=self.device,
                )
            a.clear_forces()
            self._pipeline.collide(a, self._contacts)
            self.solver.step(a, b, self._control, self._contacts, self.h)
            a, b = b, a
        if a is not self._states[0]:
            wp.copy(self._states[0].particle_q, a.particle_q)
            wp.copy(self._states[0].particle_qd, a.particle_qd)

    def _run_step(self) -> None:
        if not self.config['graph_capture']:
            self._substeps()
            return
        if self._graph is None:
            with wp.ScopedCapture(device=self.device) as capture:
                self._substeps()
            self._graph = capture.graph
        wp.capture_launch(self._graph)

    def _vertices_now(self) -> np.ndarray:
        return self._states[0].particle_q.numpy().astype(float)

    # -- ClothEngine --------------------------------------------------------------------------

    def _reset(self, displacement: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        q = (self._rest + displacement).astype(np.float32)
        for state in self._states:
            state.particle_q.assign(q)
            state.particle_qd.zero_()
        self._target[0], self._target[1] = left, right
        self._start.assign(self._target.astype(np.float32))
        self._velocity.zero_()
        return self._vertices_now()

    def _step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        goal = np.stack([left, right])
        self._start.assign(self._target.astype(np.float32))
        self._velocity.assign(((goal - self._target) / self.dt).astype(np.float32))
        self._run_step()
        self._target[:] = goal
        return self._vertices_now()

    def close(self) -> None:
        self._graph = None
        self.solver = None
        self.model = None  # type: ignore[assignment]
