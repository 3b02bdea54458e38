"""
The project's one deadline rule and its one accuracy tolerance.

- `deadline_check`: does an engine's step p99 leave room for the round trip at a rate? The rule:
  a configuration meets a rate when its step p99 is under `budget` x the period (1 / rate; budget
  0.5 by default: the other half is the round trip, two DDS hops and the messages in Python). Used
  by the settings sweep's recommendation, `cloth-bench hil`'s warm-up check and its remedy line,
  and `--find-rate`'s estimate.
- `holds_rate`: did real-time runs keep deadline misses (latency over one period) under a
  threshold? The median over runs is judged, so one burst of late states on a shared machine does
  not decide alone.
- `cd_tolerance` and `within_tolerance`: a configuration is accurate enough when its CD is at most
  the best CD + max(tol_rel x best, tol_abs).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Iterable

from cloth_bench_ros.command_options import COMMAND_FLAGS

DEADLINE_BUDGET = 0.5  # the step's share of the period; the rest is the round trip
# a rate is held when under this share of the deadlines is missed (hil --miss-threshold)
MISS_THRESHOLD = COMMAND_FLAGS['miss_threshold'].default


def deadline_rule(budget: float = DEADLINE_BUDGET) -> str:
    """Return the deadline rule in words, as the output states it."""
    return (
        f'deadline rule: a configuration meets a rate when its step p99 is under {budget:g} x the'
        ' period (1 / rate); the rest of the period is the round trip'
    )


@dataclass(frozen=True)
class DeadlineCheck:
    """One configuration's step p99 against one rate's period and the budget."""

    rate_hz: float
    step_p99_s: float
    budget: float = DEADLINE_BUDGET

    @property
    def period_s(self) -> float:
        """Return one period, 1 / rate."""
        return 1.0 / self.rate_hz

    @property
    def allowance_s(self) -> float:
        """Return the step's share of the period: budget x period."""
        return self.budget * self.period_s

    @property
    def meets(self) -> bool:
        """Return whether the step p99 is under budget x period (False if not measured)."""
        return math.isfinite(self.step_p99_s) and self.step_p99_s < self.allowance_s

    @property
    def exceeds_period(self) -> bool:
        """Return whether the step p99 alone is over one period: at least 1 % of states late."""
        return math.isfinite(self.step_p99_s) and self.step_p99_s > self.period_s

    @property
    def rate_met_hz(self) -> float:
        """Return the highest rate at which this step p99 would meet the rule (nan: unmeasured)."""
        if not math.isfinite(self.step_p99_s) or self.step_p99_s <= 0:
            return math.nan
        return self.budget / self.step_p99_s

    def verdict(self) -> str:
        """Return a few words: how the step p99 compares with the period and the allowance."""
        p99, period = 1e3 * self.step_p99_s, 1e3 * self.period_s
        if self.exceeds_period:
            return (
                f'step p99 {p99:.3g} ms exceeds the {period:g} ms period at {self.rate_hz:g} Hz:'
                ' over 1 % of the states will be late whatever the transport'
            )
        if not self.meets:
            return (
                f'step p99 {p99:.3g} ms is over {self.budget:g} x the {period:g} ms period at'
                f' {self.rate_hz:g} Hz: {period - p99:.3g} ms left for the round trip, expect'
                ' deadline misses'
            )
        return (
            f'step p99 {p99:.3g} ms is under {self.budget:g} x the {period:g} ms period at'
            f' {self.rate_hz:g} Hz'
        )


def deadline_check(
    step_p99_s: float, rate_hz: float, budget: float = DEADLINE_BUDGET
) -> DeadlineCheck:
    """Return the rule applied to one step p99 (s) at one rate (Hz)."""
    return DeadlineCheck(float(rate_hz), float(step_p99_s), float(budget))


def holds_rate(miss_fractions: Iterable[float], threshold: float = MISS_THRESHOLD) -> bool:
    """Return whether the median share of missed deadlines over runs is under the threshold."""
    values = sorted(float(v) for v in miss_fractions)
    if not values or any(math.isnan(v) for v in values):
        return False
    n = len(values)
    median = values[n // 2] if n % 2 else 0.5 * (values[n // 2 - 1] + values[n // 2])
    return median < threshold


def cd_tolerance(best_cd: float, tol_rel: float, tol_abs: float) -> float:
    """Return how far above the best CD a configuration may be: max(tol_rel x best, tol_abs)."""
    return max(tol_rel * best_cd, tol_abs)


def within_tolerance(cd: float, best_cd: float, tolerance_m: float) -> bool:
    """Return whether a CD is accurate enough: finite and at most the best + the tolerance."""
    return math.isfinite(cd) and cd <= best_cd + tolerance_m
