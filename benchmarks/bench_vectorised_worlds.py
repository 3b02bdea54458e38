"""
Several trials at once: Newton's vectorised worlds and MuJoCo's `rollout` against one at a time.

What an identification's batch of trials (a CMA-ES generation, several TPE suggestions) would
gain on this machine's CPU from being stepped together, measured in one process:

- Newton (Warp's CPU device, or --device): the N trials of a generation as N worlds of one
  Newton model, each world the towel with its own parameters (mass, membrane, its damping,
  bending, friction drawn within a factor 1.5 of the preset, as a CMA-ES generation has them),
  stepped together, against
  the same N trials run one after the other by the engine (NewtonCloth, as identification runs
  them), for N = 1, 2, 4, 8. Prints steps per second per world both ways, their ratio, the set-up
  time both ways, and how far any world's vertices end from its trial run alone.
- MuJoCo: `mujoco.rollout` (one call for the N trials, each with its own MjModel, with 1 and 2
  threads) against today's per-step loop (the engine, one trial after the other). The engine
  writes the grasped corners' qpos and qvel before every internal step, which rollout cannot
  (its controls are ctrl, applied forces, mocap poses and equality switches; the corners are flex
  vertices, not mocap bodies, and MuJoCo attaches no mocap body to an elastic flex), so both hold
  the corners where they start: the loop by the engine's grasp, rollout by the engine's weight
  cancelling force on the heavy corners (the difference of the two is printed).

The motion is the bundled towel fling at 100 Hz on the coarse default 11 x 15 mesh, its first
--seconds (the settle phase); MuJoCo's corners stay at the first target.

    .venv/bin/python benchmarks/bench_vectorised_worlds.py [--worlds 1 2 4 8]
        [--models xpbd vbd] [--seconds 1] [--repeats 2] [--device cpu] [--no-mujoco]
        [--no-newton]

About a minute of CPU with the defaults (XPBD and MuJoCo); `--models xpbd vbd` adds VBD, about
three more.

Steps per second are given from the process's CPU time (what one core gives a trial, which the
load of a shared machine hardly changes; identification already runs a trial per core on its
Dask workers) and from the wall time. With --device cuda the Newton rows compare the same on a
GPU (the CPU time is then the host's).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.task import initial_displacement
from cloth_bench_ros.core.trajectory import full_targets
from cloth_bench_ros.engines import engine_class, make_engine
from cloth_bench_ros.engines.presets import load_preset
import numpy as np

RATE_HZ = 100.0
SPREAD = 1.5  # a generation's parameters lie within this factor of the preset
# The parameters a generation varies: identification's defaults (identify/study.py).
VARIED = {
    'newton:xpbd': ('mass', 'spring_stiffness', 'spring_damping', 'bending', 'friction'),
    'newton:vbd': ('mass', 'tri_stiffness', 'tri_damping', 'bending', 'friction'),
    'mujoco': ('mass', 'young', 'poisson', 'thickness', 'damping'),
}
# What every world of one Newton model must share (settings of the model or of its solver).
SHARED = (
    'model', 'timestep', 'substeps', 'solver_iterations', 'self_collision', 'device',
    'contact_stiffness', 'contact_damping',
)


def generation(
    engine: str, n: int, model: str | None = None, device: str = 'cpu', seed: int = 0
) -> list[dict]:
    """Return `n` parameter sets around the towel preset, as a CMA-ES generation has them."""
    cls = engine_class(engine)
    preset = {**load_preset(engine, 'towel', 'dynamic'), **({'model': model} if model else {})}
    if engine == 'newton':
        preset['device'] = device
    base = cls.validate_params(preset)
    schema = {p.name: p for p in cls.params}
    rng = np.random.default_rng(seed)
    trials = []
    for _ in range(n):
        params = dict(preset)
        for name in VARIED[f'{engine}:{model}' if model else engine]:
            value = float(base[name]) * SPREAD ** rng.uniform(-1, 1)
            params[name] = min(float(schema[name].high), max(float(schema[name].low), value))
        trials.append(params)
    return trials


class NewtonWorlds:
    """
    Trials of one Newton cloth model, each with its own parameters, as the worlds of one model.

    Each world is the engine's own scene (NewtonCloth's builder), so a world steps as its trial
    alone does: the same solver and substeps, the grasp kernel over every world's corners. Two
    things Newton does not keep per world are set here: the cloth-table friction (and contact
    stiffness) is the mean of a model-wide value and the table's (XPBD: arithmetic mean of the
    friction; VBD: geometric mean of it, arithmetic of stiffness and damping), so the model-wide
    side is made neutral and each world's table carries the rest; and merging worlds recombines
    their VBD colourings, which changes each world's Gauss-Seidel order (worlds of identical
    parameters then end centimetres apart), so every world keeps the colour order of its own
    model.
    """

    def __init__(self, rate_hz: float, trials: list[dict]) -> None:
        import newton
        from cloth_bench_ros.engines.newton_cloth import _move_grasps, NewtonCloth
        import warp as wp

        self._wp, self._move = wp, _move_grasps
        self._engine_substeps = NewtonCloth._substeps  # the engine's loop, run on every world
        engines = [make_engine('newton', rate_hz, p) for p in trials]
        first = engines[0]
        for name in SHARED:
            if any(e.config[name] != first.config[name] for e in engines):
                raise ValueError(f'the worlds of one model must share {name}')
        if first.config['self_collision']:
            raise ValueError('the worlds of one model are built here without self-collision')
        self.worlds, self.n = len(engines), len(first._rest)
        self.dt, self.h, self.substeps = first.dt, first.h, first.substeps
        self.device, self._rest = first.device, first._rest
        vbd = first.config['model'] == 'vbd'
        n = self.n
        with wp.ScopedDevice(self.device):
            builder = newton.ModelBuilder(gravity=(0.0, 0.0, scene.GRAVITY))
            for e in engines:
                world = e._build_model(finalize=False)
                mu, ke, kd = (float(e.config[k]) for k in ('friction', 'contact_stiffness',
                                                           'contact_damping'))
                f32 = np.float32(mu)
                world.shape_material_mu[0] = float(f32 * f32) if vbd else 2 * mu
                world.shape_material_ke[0], world.shape_material_kd[0] = 2 * ke, 2 * kd
                builder.add_world(world)
            if vbd:
                groups = world.particle_color_groups
                builder.set_coloring(
                    [np.concatenate([np.asarray(g) + w * n for w in range(self.worlds)])
                     for g in groups]
                )
            self.model = model = builder.finalize()
            # model-wide: neutral in the means above; XPBD without particle-particle contact
            model.soft_contact_ke = model.soft_contact_kd = 0.0
            model.soft_contact_mu = 1.0 if vbd else 0.0
            if not vbd:
                model.particle_max_radius = 0.0
                model.particle_grid = None
            self._states = (model.state(), model.state())
            self._control = model.control()
            self._pipeline = newton.CollisionPipeline(model)
            self._contacts = self._pipeline.contacts()
            first.model = model
            self.solver = first._make_solver()  # the engine's solver and settings, on all worlds
            corners = [w * n + k for w in range(self.worlds) for k in first._corners]
            self._index = wp.array(corners, dtype=wp.int32)
            self._start = wp.zeros(2 * self.worlds, dtype=wp.vec3)
            self._velocity = wp.zeros(2 * self.worlds, dtype=wp.vec3)
        for e in engines:
            e.close()
        self._target = np.zeros((self.worlds, 2, 3))
        self._graph: Any = None

    def reset(self, seed: int, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Every world in the task's seeded initial state (as ClothEngine.reset)."""
        from cloth_bench_ros.core.scene import ClothGrid

        shift = initial_displacement(ClothGrid(), seed, left, right)
        q = np.tile(self._rest + shift, (self.worlds, 1)).astype(np.float32)
        for state in self._states:
            state.particle_q.assign(q)
            state.particle_qd.zero_()
        self._target[:, 0], self._target[:, 1] = left, right
        self._start.assign(self._target.reshape(-1, 3).astype(np.float32))
        self._velocity.zero_()
        return self.vertices()

    def vertices(self) -> np.ndarray:
        """Return every world's vertices, shape (worlds, n, 3)."""
        return self._states[0].particle_q.numpy().astype(float).reshape(self.worlds, self.n, 3)

    def _substeps(self) -> None:
        self._engine_substeps(self, self._move, 2 * self.worlds)  # every world's two corners

    def step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Advance every world by dt, grippers to the same targets (as NewtonCloth.step)."""
        wp = self._wp
        goal = np.stack([left, right])[None]
        self._start.assign(self._target.reshape(-1, 3).astype(np.float32))
        velocity = (goal - self._target) / self.dt
        self._velocity.assign(velocity.reshape(-1, 3).astype(np.float32))
        if self._graph is None:
            with wp.ScopedCapture(device=self.device) as capture:
                self._substeps()
            self._graph = capture.graph
        wp.capture_launch(self._graph)
        self._target[:] = goal
        return self.vertices()


def newton_row(model: str, n: int, steps: int, device: str) -> dict:
    """Time a generation of `n` trials one by one and as `n` worlds; compare the vertices."""
    targets = full_targets('dynamic', RATE_HZ)
    trials = generation('newton', n, model, device)
    left, right = targets.left, targets.right
    alone, setup_seq, step_seq, cpu_seq = [], 0.0, 0.0, 0.0
    for params in trials:
        t0 = time.perf_counter()
        engine = make_engine('newton', RATE_HZ, params)
        engine.start(0, left[0], right[0])
        t1, c1 = time.perf_counter(), time.process_time()
        for k in range(1, steps):
            vertices = engine.step(left[k], right[k])
        step_seq += time.perf_counter() - t1
        cpu_seq += time.process_time() - c1
        setup_seq += t1 - t0
        alone.append(vertices)
        engine.close()
    t0 = time.perf_counter()
    worlds = NewtonWorlds(RATE_HZ, trials)
    worlds.reset(0, left[0], right[0])
    worlds.step(left[0], right[0])  # as engine.start: the first step records the graph
    worlds.reset(0, left[0], right[0])
    t1, c1 = time.perf_counter(), time.process_time()
    for k in range(1, steps):
        together = worlds.step(left[k], right[k])
    step_batch = time.perf_counter() - t1
    cpu_batch = time.process_time() - c1
    return {
        'seq': n * (steps - 1) / cpu_seq,
        'batch': n * (steps - 1) / cpu_batch,
        'seq_wall': n * (steps - 1) / step_seq,
        'batch_wall': n * (steps - 1) / step_batch,
        'setup_seq': setup_seq,
        'setup_batch': t1 - t0,
        'diff': max(float(np.abs(together[i] - alone[i]).max()) for i in range(n)),
    }


def mujoco_row(n: int, steps: int, threads: tuple[int, ...] = (1, 2)) -> dict:
    """Time `n` trials with the engine's per-step loop and with mujoco.rollout."""
    import mujoco
    from mujoco import rollout

    targets = full_targets('dynamic', RATE_HZ)
    left, right = targets.left[0], targets.right[0]
    trials = generation('mujoco', n)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    engines, initial, force, finals = [], [], [], []
    for params in trials:
        engine = make_engine('mujoco', RATE_HZ, params)
        engine.reset(0, left, right)
        state = np.empty(mujoco.mj_stateSize(engine.model, spec))
        mujoco.mj_getState(engine.model, engine.data, state, spec)
        initial.append(state)
        force.append(engine.data.qfrc_applied.copy())
        engines.append(engine)
    start, cpu = time.perf_counter(), time.process_time()
    for engine in engines:
        for _ in range(1, steps):
            engine.step(left, right)
        finals.append(engine.data.qpos.copy())
    loop, loop_cpu = time.perf_counter() - start, time.process_time() - cpu
    substeps = engines[0].substeps
    row = {'substeps': substeps, 'loop': n * (steps - 1) / loop_cpu,
           'loop_wall': n * (steps - 1) / loop}
    models = [e.model for e in engines]
    control = np.stack(force)[:, None, :]
    nq = models[0].nq
    for nthread in threads:
        data = [mujoco.MjData(models[0]) for _ in range(nthread)]
        rollout.rollout(models, data, np.stack(initial), control,
                        control_spec=mujoco.mjtState.mjSTATE_QFRC_APPLIED, nstep=substeps)
        start, cpu = time.perf_counter(), time.process_time()
        states, _ = rollout.rollout(
            models, data, np.stack(initial), control,
            control_spec=mujoco.mjtState.mjSTATE_QFRC_APPLIED, nstep=(steps - 1) * substeps,
        )
        took, took_cpu = time.perf_counter() - start, time.process_time() - cpu
        row[f'rollout{nthread}'] = n * (steps - 1) / took_cpu
        row[f'rollout{nthread}_wall'] = n * (steps - 1) / took
        row['diff'] = max(
            float(np.abs(states[i, -1, 1:1 + nq] - finals[i]).max()) for i in range(n)
        )
    for engine in engines:
        engine.close()
    return row


def best(measure: Any, repeats: int, rates: tuple[str, ...], *args: Any) -> dict:
    """Return `measure(*args)` run `repeats` times, each rate the highest seen (a loaded CPU)."""
    rows = [measure(*args) for _ in range(max(1, repeats))]
    return {**rows[-1], **{key: max(r[key] for r in rows) for key in rates}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--worlds', type=int, nargs='+', default=[1, 2, 4, 8])
    parser.add_argument(
        '--models', nargs='+', default=['xpbd'], choices=['xpbd', 'vbd'],
        help='vbd: add it (a step costs 7 times an XPBD one: minutes)',
    )
    parser.add_argument('--seconds', type=float, default=1.0, help='of the fling, from its start')
    parser.add_argument(
        '--repeats', type=int, default=2, help='runs of each row; the fastest counts (load)'
    )
    parser.add_argument(
        '--device', default='cpu', help="Newton's device (cpu, cuda, cuda:N); MuJoCo: the CPU"
    )
    parser.add_argument('--no-newton', action='store_true')
    parser.add_argument('--no-mujoco', action='store_true')
    args = parser.parse_args()
    if not args.no_newton:
        from cloth_bench_ros.engines.base import EngineError
        from cloth_bench_ros.engines.newton_cloth import resolve_device

        try:
            resolve_device(args.device)
        except EngineError as exc:
            parser.error(str(exc))
    steps = int(round(args.seconds * RATE_HZ)) + 1
    print(f'towel fling, 11 x 15 mesh, {RATE_HZ:.0f} Hz, first {args.seconds:g} s, Newton on '
          f'{args.device}: steps per second per trial, from the CPU time the process used (what '
          'a core gives; stable under load) and from the wall time (as measured, load included)')
    rates = ('seq', 'batch', 'seq_wall', 'batch_wall')
    if not args.no_newton:
        print(f'\n{"Newton":<6} {"N":>2} | {"CPU: 1-by-1":>11} {"worlds":>7} {"ratio":>5} | '
              f'{"wall: 1-by-1":>12} {"worlds":>7} {"ratio":>5} | {"set-up s":>12} | max |dx| m')
        for model in args.models:
            for n in args.worlds:
                r = best(newton_row, args.repeats, rates, model, n, steps, args.device)
                print(f'{model:<6} {n:>2} | {r["seq"]:>11.1f} {r["batch"]:>7.1f} '
                      f'{r["batch"] / r["seq"]:>5.2f} | {r["seq_wall"]:>12.1f} '
                      f'{r["batch_wall"]:>7.1f} {r["batch_wall"] / r["seq_wall"]:>5.2f} | '
                      f'{r["setup_seq"]:>5.2f} / {r["setup_batch"]:<4.2f} | {r["diff"]:.2g}',
                      flush=True)
    if not args.no_mujoco:
        print(f'\n{"MuJoCo":<6} {"N":>2} | {"CPU: loop":>9} {"rollout 1":>9} {"ratio":>5} '
              f'{"rollout 2":>9} {"ratio":>5} | {"wall: loop":>10} {"rollout 1":>9} {"ratio":>5} '
              f'{"rollout 2":>9} {"ratio":>5} | max |dq| m')
        keys = ('loop', 'rollout1', 'rollout2', 'loop_wall', 'rollout1_wall', 'rollout2_wall')
        for n in args.worlds:
            r = best(mujoco_row, args.repeats, keys, n, steps)
            cells = []
            for suffix in ('', '_wall'):
                base = r['loop' + suffix]
                cells.append(
                    f'{base:>{10 if suffix else 9}.1f} '
                    + ' '.join(f'{r[f"rollout{t}{suffix}"]:>9.1f} '
                               f'{r[f"rollout{t}{suffix}"] / base:>5.2f}' for t in (1, 2))
                )
            print(f'{"shell":<6} {n:>2} | {cells[0]} | {cells[1]} | {r["diff"]:.2g}', flush=True)


if __name__ == '__main__':
    main()
