"""
Multi-fidelity identification (`--fidelity prune` or `coarse`): most trials stopped at a rung.

Every trial is scored first at a cheaper rung (its `partial` value, reported to Optuna as the
trial's intermediate value). Once STARTUP trials have a partial value, a trial whose partial value
is above a quantile of the partial values seen so far stops there and is told to Optuna as pruned
(TPE uses a pruned trial's intermediate value, CMA-ES leaves it out); the others are scored in
full, as a `full` trial is. The rungs:

- prune: the first RUNG of each bag's frames of the window, on the trial's own mesh; a kept trial
  runs on from there. Pruned above the KEEP quantile of every partial value so far.
- coarse: the whole window on coarser meshes first (`coarse_grids`: a ladder of up to
  COARSE_RUNGS meshes, fewer where the engine says its `screen_halvings` are fewer (PyBullet:
  one), each with half the vertices along each side of the next finer one; the
  engines scale their spacing-dependent parameters, so it is the same material), coarsest first;
  a trial kept at every rung is then run whole on its own mesh, so its value is the one `full`
  gives. Pruned at a rung above the COARSE_KEEP quantile of that rung's last COARSE_WINDOW values
  (the sampler's later trials are better than its first, so a quantile over every value so far
  would keep more and more).

A pruned trial counts toward the trial budget (`--trials N` or auto) and is in the convergence
curve without a value. `full` (the default) is the sampler as before: every trial over the whole
motion on its own mesh.
"""

from __future__ import annotations

import math
from typing import Any

from cloth_bench_ros.core.cloth_size import cloth_grid
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.errors import InputError
import numpy as np
from optuna.trial import TrialState

FIDELITIES = ('full', 'prune', 'coarse')
RUNG, KEEP, STARTUP = 0.25, 0.3, 8
COARSE_KEEP, COARSE_WINDOW, COARSE_RUNGS = 0.2, 16, 2


def coarse_grids(
    grid: tuple[int, int] | None, size: tuple[float, float] | None = None,
    rungs: int = COARSE_RUNGS,
) -> tuple[tuple[int, int], ...]:
    """
    Return the rungs' meshes for `coarse`, coarsest first: at most `rungs` (halvings of the mesh).

    Each is (nx + 1) // 2 by (nz + 1) // 2 of the next finer one (at least 3 x 3) where that has at
    most half its vertices. InputError where the mesh has none.
    """
    mesh = cloth_grid(grid, size) or ClothGrid()
    ladder = [(mesh.nx, mesh.nz)]
    while len(ladder) <= rungs:
        nx, nz = ladder[-1]
        coarse = (max(3, (nx + 1) // 2), max(3, (nz + 1) // 2))
        if 2 * coarse[0] * coarse[1] > nx * nz:
            break
        ladder.append(coarse)
    if len(ladder) == 1:
        raise InputError(
            f'--fidelity coarse: the {mesh.nx} x {mesh.nz} mesh has no coarser one to screen on '
            '(one with at most half its vertices; 3 x 3 is the coarsest); use --fidelity prune '
            'or full'
        )
    return tuple(reversed(ladder[1:]))


def screen_rungs(engine: str) -> int:
    """Return how many coarser meshes `coarse` screens `engine`'s trials on (its halvings)."""
    return min(COARSE_RUNGS, engine_class(engine).screen_halvings)


def check_fidelity(
    fidelity: str, grid: tuple[int, int] | None, size: tuple[float, float] | None, engine: str,
) -> None:
    """Raise InputError for an unknown fidelity, or for `coarse` on a mesh with no coarser one."""
    if fidelity not in FIDELITIES:
        raise InputError(f'unknown fidelity {fidelity!r} (valid: {", ".join(FIDELITIES)})')
    if fidelity == 'coarse':
        coarse_grids(grid, size, screen_rungs(engine))


class Pruner:
    """The partial values of a sampler's study, and the rung and threshold of the next trial."""

    def __init__(
        self, fidelity: str, study: Any, grid: tuple[int, int] | None,
        size: tuple[float, float] | None, engine: str,
    ) -> None:
        self.fidelity = fidelity
        self.grids = coarse_grids(grid, size, screen_rungs(engine)) if fidelity == 'coarse' else ()
        self.partials: dict[int, list[float]] = {}  # per rung (step)
        for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number):
            self._keep(t.intermediate_values)  # a resumed study keeps its partial values

    def _keep(self, values: dict) -> None:
        for step, v in values.items():
            if math.isfinite(v):
                self.partials.setdefault(int(step), []).append(float(v))

    def _above(self, step: int) -> float | None:
        values = self.partials.get(step, [])
        if len(self.partials.get(0, [])) < STARTUP or not values:
            return None  # the first trials run whole, their partial values measured
        if self.grids:
            return float(np.quantile(values[-COARSE_WINDOW:], COARSE_KEEP))
        return float(np.quantile(values, KEEP))

    def rung(self) -> dict[str, Any]:
        """Return the next trial's rung fields (objective.Trial): {} when not multi-fidelity."""
        if self.fidelity == 'full':
            return {}
        if self.grids:
            return {'ladder': tuple((g, self._above(i)) for i, g in enumerate(self.grids))}
        return {'rung': RUNG, 'prune_above': self._above(0)}

    def tell(self, study: Any, trial: Any, result: dict) -> bool:
        """Tell Optuna a trial's result; True where it was handled (pruned or complete)."""
        partials = result.get('partials', [result.get('partial')])
        values = {i: float(v) for i, v in enumerate(partials) if v is not None}
        self._keep(values)
        for step, value in values.items():
            if math.isfinite(value):
                trial.report(value, step)
        if result['status'] == 'pruned':
            study.tell(trial, state=TrialState.PRUNED)
            return True
        if result['status'] == 'ok':
            study.tell(trial, result['value'])
            return True
        return False
