"""The one interface every cloth engine implements, and the checks they share."""

from __future__ import annotations

import abc
from dataclasses import dataclass
import math
from typing import Any, Callable, ClassVar, Mapping

from cloth_bench_ros import validation
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.task import grasped_corners, initial_displacement
from cloth_bench_ros.errors import ClothBenchError
import numpy as np


class EngineError(ClothBenchError, ValueError):
    """A user error in choosing or configuring an engine (unknown name, bad parameter)."""


@dataclass(frozen=True)
class Param:
    """One engine parameter: default, unit and the closed range [low, high] it must lie in."""

    name: str
    default: float | int | str | bool
    unit: str
    low: float | None = None
    high: float | None = None
    doc: str = ''
    choices: tuple[str, ...] = ()
    check: Callable[[object, str], object] | None = None  # a text parameter's validation rule

    def validate(self, value: object) -> object:
        """`value` checked against this parameter's type and range (validation's rules)."""
        name = f'parameter {self.name}'
        try:
            if self.check is not None:
                return self.check(value, name)
            if self.choices:
                return validation.choice(value, name, self.choices)
            if isinstance(self.default, bool):
                return validation.boolean(value, name)
            if isinstance(self.default, int):
                return validation.integer(value, name, _int_bound(self.low), _int_bound(self.high))
            return validation.number(value, name, self.low, self.high, unit=self.unit)
        except validation.InputError as exc:
            raise EngineError(str(exc)) from None


def _int_bound(bound: float | None) -> int | None:
    return None if bound is None else int(bound)


def spacing_ratio(grid: ClothGrid, params_grid: ClothGrid) -> float:
    """Return the mesh spacing of `grid` over that of `params_grid` (geometric mean of x and z)."""
    (dx, dz), (px, pz) = grid.spacing, params_grid.spacing
    return math.sqrt((dx / px) * (dz / pz))


def params_for_grid(
    cls: type[ClothEngine],
    params: Mapping[str, Any],
    rate_hz: float,
    grid: ClothGrid | None,
    params_grid: ClothGrid | None = None,
) -> dict[str, Any]:
    """
    Return an engine's `params`, set for `params_grid`, for the same cloth on `grid`.

    The one place where a mesh other than the one the parameters were set for is given the same
    material (`--grid`, the settings sweep's mesh axis, identification, `converge`): presets,
    overrides and identified values are set for the default mesh (`ClothGrid()`, 11 x 15), so
    `params_grid` defaults to it. On the mesh they were set for they are returned unchanged.
    """
    grid, params_grid = grid or ClothGrid(), params_grid or ClothGrid()
    try:
        rate_hz = validation.rate_hz(rate_hz)  # as the engine will refuse it, before any use
    except validation.InputError as exc:
        raise EngineError(str(exc)) from None
    if grid.spacing == params_grid.spacing:
        return dict(params)
    return cls.params_for_spacing(params, spacing_ratio(grid, params_grid), rate_hz)


@dataclass(frozen=True)
class Divergence:
    step: int
    reason: str


class Instability(Exception):
    """An engine's own report that its state went unstable: a divergence, never a bug."""


# Divergence thresholds: a cloth vertex this far from the grippers, or this fast, has exploded.
MAX_DISTANCE_FROM_GRIPPERS = 5.0  # m (the cloth is 0.86 m across its diagonal)
MAX_VERTEX_SPEED = 100.0  # m/s
# What every engine's state is checked for after each step (`check_divergence`).
STATE_CHECKS = (
    'non-finite vertex positions',
    f'a vertex more than {MAX_DISTANCE_FROM_GRIPPERS:g} m from the grippers',
    f'a vertex faster than {MAX_VERTEX_SPEED:g} m/s',
)


def check_divergence(
    vertices: np.ndarray, previous: np.ndarray | None, dt: float, grippers_mid: np.ndarray
) -> str | None:
    """Why this state counts as diverged, or None."""
    if not np.isfinite(vertices).all():
        return 'non-finite vertex positions'
    reach = float(np.abs(vertices - grippers_mid).max())
    if reach > MAX_DISTANCE_FROM_GRIPPERS:
        return f'a vertex is {reach:.1f} m from the grippers'
    if previous is not None:
        speed = float(np.linalg.norm(vertices - previous, axis=1).max() / dt)
        if speed > MAX_VERTEX_SPEED:
            return f'a vertex moves at {speed:.0f} m/s'
    return None


class ClothEngine(abc.ABC):
    """
    A cloth simulator for the benchmark scene: cloth, table, two point grasps.

    Subclasses set `name` and `params`, build the scene, put the cloth in the task's initial
    state in `_reset` and advance it in `_step`. The task's set-up (grasped corners, the seeded
    initial state) is core/task.py's: engines only apply it and step the physics.

    A divergence is what `instability_signals` names: the state checks, and whatever the engine
    itself reports as unstable, raised from `_step` as `Instability`. Any other exception of
    `_step` is a bug and goes to the caller.
    """

    name: ClassVar[str]
    params: ClassVar[tuple[Param, ...]]
    # The engine's own signals that it went unstable, besides STATE_CHECKS (docs, `engines`).
    instability_signals: ClassVar[tuple[str, ...]] = ()
    # Multi-fidelity `coarse`: how many halvings of the mesh still rank parameters as it does.
    screen_halvings: ClassVar[int] = 2
    device: str = 'cpu'  # the compute device this engine runs on (`device_for` its params)

    def __init__(
        self,
        rate_hz: float,
        params: Mapping[str, Any] | None = None,
        grid: ClothGrid | None = None,
    ) -> None:
        try:
            self.rate_hz = validation.rate_hz(rate_hz)
        except validation.InputError as exc:
            raise EngineError(str(exc)) from None
        self.grid = grid or ClothGrid()
        self.config = self.validate_params(params or {})
        self.divergence: Divergence | None = None
        self.steps = 0
        self._vertices: np.ndarray | None = None
        self._mid = np.zeros(
            3
        )  # scratch of the divergence check, so a step allocates nothing for it
        self._scratch: np.ndarray | None = None
        self._row: np.ndarray | None = None
        self._rest = self.grid.vertices()
        self._corners = grasped_corners(self.grid)
        if (
            'timestep' in self.config and 'substeps' in self.config
        ):  # the one substep rule of the engines
            self.substeps = self.internal_steps(
                float(self.config['timestep']), int(self.config['substeps'])
            )
            self.h = self.dt / self.substeps

    @classmethod
    def validate_params(cls, params: Mapping[str, Any]) -> dict[str, Any]:
        """Defaults overlaid with `params`; EngineError on unknown names or bad values."""
        schema = {p.name: p for p in cls.params}
        unknown = sorted(set(params) - set(schema))
        if unknown:
            raise EngineError(
                f'unknown {cls.name} parameter {", ".join(unknown)} (known: {", ".join(schema)})'
            )
        config: dict[str, Any] = {p.name: p.default for p in cls.params}
        config.update({k: schema[k].validate(v) for k, v in params.items()})
        return config

    @classmethod
    def params_for_spacing(
        cls, params: Mapping[str, Any], ratio: float, rate_hz: float
    ) -> dict[str, Any]:
        """
        Return `params`, set for one mesh spacing, restated for a spacing `ratio` times it.

        `rate_hz` is the engine's step rate (an internal step the scaling needs depends on it).

        The parameters of an engine that depend on the spacing (a quantity per vertex or per edge
        that a finer mesh would otherwise turn into another cloth) are scaled so that the mesh
        changes only the resolution; the default scales nothing. Called by `params_for_grid`.
        """
        return dict(params)

    @classmethod
    def device_for(cls, params: Mapping[str, Any]) -> str:
        """Return the device an engine with `params` runs on (`cpu` unless an engine says)."""
        return 'cpu'

    @classmethod
    def devices(cls) -> tuple[str, ...]:
        """Return the devices this engine can run on, on this machine."""
        return ('cpu',)

    @classmethod
    def version(cls) -> str:
        """Version of the underlying simulator."""
        return 'unknown'

    @classmethod
    def warm(cls) -> None:
        """Do once what would make an engine's first run slow (e.g. compiling kernels)."""

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    def internal_steps(self, timestep: float, least: int) -> int:
        """Return the internal steps per step: at least `least`, none longer than `timestep`."""
        return max(least, math.ceil(self.dt / timestep - 1e-9))

    @property
    def diverged(self) -> bool:
        return self.divergence is not None

    @property
    def faces(self) -> np.ndarray:
        return self.grid.faces()

    def reset(self, seed: int, left_xyz: np.ndarray, right_xyz: np.ndarray) -> np.ndarray:
        """Build the scene, grasped corners at the grippers; the seed perturbs the cloth."""
        self.divergence = None
        self.steps = 0
        left, right = np.asarray(left_xyz, float), np.asarray(right_xyz, float)
        self._vertices = self._reset(
            initial_displacement(self.grid, int(seed), left, right), left, right
        )
        return self._vertices

    def start(self, seed: int, left_xyz: np.ndarray, right_xyz: np.ndarray) -> np.ndarray:
        """
        Reset, take one throwaway step, reset again; return the state at the first target.

        Every run starts this way (the simulator node, the direct study path, identification):
        the step pays an engine's first-call costs before any deadline, and all of them start
        from the same state.
        """
        self.reset(seed, left_xyz, right_xyz)
        self.step(left_xyz, right_xyz)
        return self.reset(seed, left_xyz, right_xyz)

    def step(self, left_xyz: np.ndarray, right_xyz: np.ndarray) -> np.ndarray:
        """Advance dt with the grippers moved to the targets; the vertices (n, 3) after it."""
        if self._vertices is None:
            raise RuntimeError('reset() before step()')
        self.steps += 1
        if self.divergence is not None:
            return self._vertices
        left, right = np.asarray(left_xyz, float), np.asarray(right_xyz, float)
        try:
            vertices = self._step(left, right)
        except Instability as exc:  # only the engine's own signal; any other exception is a bug
            self.divergence = Divergence(self.steps, str(exc))
            return self._vertices
        reason = self._check(vertices, left, right)
        if reason is not None:
            self.divergence = Divergence(self.steps, reason)
        self._vertices = vertices
        return vertices

    def _check(self, vertices: np.ndarray, left: np.ndarray, right: np.ndarray) -> str | None:
        """
        Return check_divergence's reason, cheaply (None when the state is sound).

        Two bounds are computed in preallocated scratch arrays; the exact reason only when a bound
        fails (NaN fails every comparison, so it gets there too).
        """
        if self._scratch is None or self._scratch.shape != vertices.shape:
            self._scratch, self._row = (
                np.empty_like(vertices, dtype=float),
                np.empty(len(vertices)),
            )
        mid, buf = self._mid, self._scratch
        np.add(left, right, out=mid)
        mid *= 0.5
        np.subtract(vertices, mid, out=buf)
        np.abs(buf, out=buf)
        reach = buf.max()
        assert self._vertices is not None  # step() checked it
        np.subtract(vertices, self._vertices, out=buf)
        np.multiply(buf, buf, out=buf)
        travel2 = buf.sum(axis=1, out=self._row).max()
        if reach <= MAX_DISTANCE_FROM_GRIPPERS and travel2 <= (MAX_VERTEX_SPEED * self.dt) ** 2:
            return None
        return check_divergence(vertices, self._vertices, self.dt, mid)

    @abc.abstractmethod
    def _reset(self, displacement: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Return the cloth's vertices at rest + `displacement`, grippers at left and right."""

    @abc.abstractmethod
    def _step(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Return the vertices after dt; Instability on the engine's own instability signal."""

    def close(self) -> None:
        """Free the simulator's resources."""
