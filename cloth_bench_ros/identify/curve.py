"""
An identification's convergence curve: best value against trials, and the budget read from it.

The trial budget chosen from the curve (`--trials auto`, AUTO): run AUTO_FIRST trials, then
double while a doubling still improves the best value by at least AUTO_TOLERANCE, up to
AUTO_MAX_TRIALS.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import optuna
from optuna.trial import TrialState

AUTO_FIRST, AUTO_MAX_TRIALS, AUTO_TOLERANCE = 32, 512, 0.02


def best_after(curve: Sequence[Sequence], n: int) -> float:
    """Return the best value among a convergence curve's first n trials (inf if none finished)."""
    values = [row[1] for row in curve[:n] if row[1] is not None]
    return min(values) if values else math.inf


def budget_reached(curve: Sequence[Sequence], n: int) -> tuple[bool, float]:
    """
    Whether n trials are enough: the doubling from n / 2 to n improved the best by < 2 %.

    Returns (enough, relative improvement of the last doubling).
    """
    before, after = best_after(curve, n // 2), best_after(curve, n)
    if not math.isfinite(after):
        return False, math.nan
    gain = 1.0 if not math.isfinite(before) else (before - after) / before
    return gain < AUTO_TOLERANCE, gain


def best_value(study: Any) -> float:
    try:
        return float(study.best_value)
    except ValueError:
        return math.nan


def finite_or_inf(value: float) -> float:
    return value if math.isfinite(value) else math.inf


def convergence(study: Any) -> list[list]:
    """Return [number, value or None, best so far or None] per finished trial (pruned too)."""
    out, best = [], math.inf
    for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number):
        if t.state not in (TrialState.COMPLETE, TrialState.FAIL, TrialState.PRUNED):
            continue
        value = t.value if t.state == TrialState.COMPLETE else None
        if value is not None:
            best = min(best, value)
        out.append([t.number, value, best if math.isfinite(best) else None])
    return out


def importance(study: Any) -> dict[str, float]:
    """Return how much each parameter explains (PED-ANOVA); {} with too few trials."""
    try:
        evaluator = optuna.importance.PedAnovaImportanceEvaluator()
        return {
            k: float(v)
            for k, v in optuna.importance.get_param_importances(study, evaluator=evaluator).items()
        }
    except Exception:  # too few complete trials, or every value equal
        return {}
