"""
Multi-fidelity identification (`--fidelity prune` or `coarse`): most trials stopped at a rung.

Every trial is scored first at a cheaper rung (its `partial` value, reported to Optuna as the
trial's intermediate value). Once STARTUP trials have a partial value, a trial whose partial value
is above a quantile of the partial values seen so far stops there and is told to Optuna as pruned
(TPE uses a pruned trial's intermediate value, CMA-ES leaves it out); the others are scored in
full, as a `full` trial is. The rungs:

- prune: the first RUNG of each bag's frames of the window, on the trial's own mesh; a kept trial
  runs on from there. Pruned above the KEEP quantile of every partial value so far.
- coarse: the whole window on a coarser mesh (`coarse_grid`: half the vertices along each side;
  the engines scale their spacing-dependent parameters, so it is the same material); a kept trial
  is then run whole on its own mesh, so its value is the one `full` gives. Pruned above the
  COARSE_KEEP quantile of the last COARSE_WINDOW partial values (the sampler's later trials are
  better than its first, so a quantile over every value so far would keep more and more).

A pruned trial counts toward the trial budget (`--trials N` or auto) and is in the convergence
curve without a value. `full` (the default) is the sampler as before: every trial over the whole
motion on its own mesh.
"""

from __future__ import annotations

import math
from typing import Any

from cloth_bench_ros.errors import InputError
import numpy as np

FIDELITIES = ('full', 'prune', 'coarse')
RUNG, KEEP, STARTUP = 0.25, 0.3, 8
COARSE_KEEP, COARSE_WINDOW = 0.2, 16


def coarse_grid(
    grid: tuple[int, int] | None, size: tuple[float, float] | None = None
) -> tuple[int, int]:
    """Return the rung's mesh for `coarse`: (nx + 1) // 2 by (nz + 1) // 2, at least 3 x 3."""
    from cloth_bench_ros.core.cloth_size import cloth_grid
    from cloth_bench_ros.core.scene import ClothGrid

    mesh = cloth_grid(grid, size) or ClothGrid()
    coarse = (max(3, (mesh.nx + 1) // 2), max(3, (mesh.nz + 1) // 2))
    if coarse[0] * coarse[1] >= mesh.nx * mesh.nz:
        raise InputError(
            f'--fidelity coarse: the {mesh.nx} x {mesh.nz} mesh has no coarser one to screen on '
            '(at least 4 x 4 vertices); use --fidelity prune or full'
        )
    return coarse


def check_fidelity(
    fidelity: str, grid: tuple[int, int] | None, size: tuple[float, float] | None = None
) -> None:
    """Raise InputError for an unknown fidelity, or for `coarse` on a mesh with no coarser one."""
    if fidelity not in FIDELITIES:
        raise InputError(f'unknown fidelity {fidelity!r} (valid: {", ".join(FIDELITIES)})')
    if fidelity == 'coarse':
        coarse_grid(grid, size)


class Pruner:
    """The partial values of a sampler's study, and the rung and threshold of the next trial."""

    def __init__(
        self, fidelity: str, study: Any, grid: tuple[int, int] | None = None,
        size: tuple[float, float] | None = None,
    ) -> None:
        self.fidelity = fidelity
        self.coarse = coarse_grid(grid, size) if fidelity == 'coarse' else None
        self.partials: list[float] = []
        for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number):
            # a resumed study keeps its partial values
            self.partials.extend(v for v in t.intermediate_values.values() if math.isfinite(v))

    def rung(self) -> dict[str, Any]:
        """Return the next trial's rung fields (objective.Trial): {} when not multi-fidelity."""
        if self.fidelity == 'full':
            return {}
        rung: dict[str, Any] = (
            {'rung_grid': self.coarse} if self.coarse is not None else {'rung': RUNG}
        )
        if len(self.partials) < STARTUP:
            return rung  # the first trials run whole, their partial values measured
        if self.coarse is not None:
            above = np.quantile(self.partials[-COARSE_WINDOW:], COARSE_KEEP)
        else:
            above = np.quantile(self.partials, KEEP)
        return {**rung, 'prune_above': float(above)}

    def tell(self, study: Any, trial: Any, result: dict) -> bool:
        """Tell Optuna a trial's result; True where it was handled (pruned or complete)."""
        from optuna.trial import TrialState

        partial = result.get('partial')
        if partial is not None and math.isfinite(partial):
            self.partials.append(float(partial))
            trial.report(float(partial), 0)
        if result['status'] == 'pruned':
            study.tell(trial, state=TrialState.PRUNED)
            return True
        if result['status'] == 'ok':
            study.tell(trial, result['value'])
            return True
        return False
