"""
Multi-fidelity identification (`--fidelity prune`): trials cut short early in the motion.

Every trial is scored first over the first RUNG of each bag's frames of the window (its `partial`
value, reported to Optuna as the trial's intermediate value). Once STARTUP trials have a partial
value, a trial whose partial value is above the KEEP quantile of the partial values seen so far
stops there and is told to Optuna as pruned (TPE uses a pruned trial's intermediate value, CMA-ES
leaves it out); the others run to the end of the window, as a `full` trial does. A pruned trial
counts toward the trial budget (`--trials N` or auto) and is in the convergence curve without a
value. `full` (the default) is the sampler as before: every trial over the whole motion.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

FIDELITIES = ('full', 'prune')
RUNG, KEEP, STARTUP = 0.25, 0.3, 8


class Pruner:
    """The partial values of a sampler's study, and the threshold a new trial is pruned above."""

    def __init__(self, fidelity: str, study: Any) -> None:
        self.active = fidelity == 'prune'
        self.partials: list[float] = []
        for t in study.get_trials(deepcopy=False):  # a resumed study keeps its partial values
            self.partials.extend(v for v in t.intermediate_values.values() if math.isfinite(v))

    def rung(self) -> tuple[float | None, float | None]:
        """Return (rung, prune_above) for the next trial: (None, None) when not multi-fidelity."""
        if not self.active:
            return None, None
        if len(self.partials) < STARTUP:
            return RUNG, None  # the first trials run whole, their partial values measured
        return RUNG, float(np.quantile(self.partials, KEEP))

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
