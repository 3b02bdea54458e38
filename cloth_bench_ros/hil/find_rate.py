"""
The highest step rate a configuration holds in the hardware-in-the-loop layout.

`find_rate` searches the rates between a lowest and a highest by bisection on a log scale: a rate
is held when the median share of missed deadlines over a few short real-time runs is under the
threshold (`holds_rate`, core/deadline.py). The lowest rate is tried first (not held: the
configuration holds no rate of the range), then the highest (held: it holds the whole range), then
the geometric middle of the bracket until its ends are within the tolerance of each other. The
rate found is the bracket's lower end, the highest rate seen held.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from pathlib import Path
from typing import Callable

from cloth_bench_ros.command_options import COMMAND_FLAGS
from cloth_bench_ros.core.deadline import (
    DEADLINE_BUDGET,
    deadline_check,
    holds_rate,
    MISS_THRESHOLD,
)
from cloth_bench_ros.hil.config import HilConfig
from cloth_bench_ros.hil.study import HilResult, lockstep_cd, run_hil
from cloth_bench_ros.hil.warmup import warmup
from cloth_bench_ros.studies.errors import RunTimeout

RATE_MIN = COMMAND_FLAGS['rate_min'].default  # Hz
RATE_MAX = COMMAND_FLAGS['rate_max'].default  # Hz
RATE_TOLERANCE = COMMAND_FLAGS['rate_tolerance'].default  # the bracket's ends within this fraction
REPEATS = COMMAND_FLAGS['repeats'].default  # runs per rate, judged on their median


@dataclass
class RateProbe:
    """One rate tried: the runs' miss shares and whether the median is under the threshold."""

    rate_hz: float
    miss_fractions: list[float]
    held: bool
    runs: list[HilResult] = field(repr=False, default_factory=list)
    failures: list[str] = field(default_factory=list)  # runs that did not finish (not held)

    def median_run(self) -> HilResult:
        """Return the run whose miss share is the median (the lower middle of an even count)."""
        shares = [miss_fraction(r) for r in self.runs]
        order = sorted(range(len(self.runs)), key=lambda i: shares[i])
        return self.runs[order[(len(order) - 1) // 2]]

    def as_dict(self) -> dict:
        return {
            'rate_hz': self.rate_hz,
            'miss_fractions': [_finite(f) for f in self.miss_fractions],  # None: run failed
            'held': self.held,
            'failures': self.failures,
        }


@dataclass
class PeakRate:
    """What the search found for one engine and mesh."""

    engine: str
    grid: str  # NXxNZ as run
    rate_hz: float  # the highest rate held (nan: not even the lowest)
    bracket: tuple[float, float]  # held, not held (inf: the highest held)
    probes: list[RateProbe]
    warmup_p99_s: float = math.nan  # the engine's step p99 at the rate found (its warm-up)
    cd: float = math.nan  # CD in lockstep at the rate found
    budget: float = DEADLINE_BUDGET

    def at_rate(self) -> RateProbe | None:
        """Return the probe of the rate found (None if none was held)."""
        return next((p for p in self.probes if p.held and p.rate_hz == self.rate_hz), None)

    def as_dict(self) -> dict:
        probe = self.at_rate()
        run = probe.median_run() if probe and probe.runs else None
        rule = deadline_check(self.warmup_p99_s, self.rate_hz, self.budget)
        return {
            'engine': self.engine,
            'grid': self.grid,
            'rate_hz': _finite(self.rate_hz),
            'bracket_hz': [_finite(v) for v in self.bracket],
            'missed': missed(run) if run else None,
            'deadline_misses': run.figures.deadline_misses if run else None,
            'skipped': run.figures.skipped if run else None,
            'lost': run.figures.lost if run else None,
            'targets': run.figures.targets if run else None,
            'miss_fraction': (
                float(sorted(probe.miss_fractions)[(len(probe.miss_fractions) - 1) // 2])
                if probe
                else None
            ),
            'latency_p999': run.figures.latency_p999 if run else None,
            'warmup_step_p99': _finite(self.warmup_p99_s),
            'rule_rate_hz': _finite(rule.rate_met_hz),
            'cd_lockstep': _finite(self.cd),
            'probes': [p.as_dict() for p in self.probes],
        }


def _finite(value: float) -> float | None:
    """Return a number for JSON: None for nan (not measured) and inf (no bound)."""
    return float(value) if math.isfinite(value) else None


def missed(result: HilResult) -> int:
    """Return the targets whose deadline passed: state late, or none (skipped or lost)."""
    f = result.figures
    return f.deadline_misses + f.skipped + f.lost


def miss_fraction(result: HilResult) -> float:
    """Return the share of targets whose deadline passed (nan without targets)."""
    n = result.figures.targets
    return missed(result) / n if n else math.nan


def find_rate(
    base: HilConfig,
    out_dir: Path,
    rate_min: float = RATE_MIN,
    rate_max: float = RATE_MAX,
    tolerance: float = RATE_TOLERANCE,
    repeats: int = REPEATS,
    threshold: float = MISS_THRESHOLD,
    lockstep: bool = True,
    budget: float = DEADLINE_BUDGET,
    log: Callable[[str], None] = print,
) -> PeakRate:
    """Return the highest rate in [rate_min, rate_max] at which `base` keeps misses under it."""
    probes: list[RateProbe] = []
    grid = 'x'.join(map(str, base.grid)) if base.grid else 'default'

    def probe(rate: float) -> bool:
        runs, fractions, failures = [], [], []
        for i in range(repeats):
            config = replace(base, rate_hz=rate, config=f'{base.config},find-rate,{i}')
            try:
                run = run_hil(config, out_dir, lockstep=False)
            except RunTimeout as exc:  # a run that did not finish in time holds nothing
                failures.append(str(exc))
                fractions.append(math.nan)
                continue
            runs.append(run)
            fractions.append(miss_fraction(run))
        held = holds_rate(fractions, threshold)
        probes.append(RateProbe(rate, fractions, held, runs, failures))
        log(
            f'  {base.engine} {grid} at {rate:.4g} Hz: missed '
            + ', '.join(f'{100 * f:.2f} %' if math.isfinite(f) else 'failed' for f in fractions)
            + (' -> held' if held else ' -> not held')
            + ''.join(f'; a run failed: {f}' for f in failures)
        )
        return held

    if not probe(rate_min):
        low, high = math.nan, rate_min
    elif probe(rate_max):
        low, high = rate_max, math.inf
    else:
        low, high = rate_min, rate_max
        while high / low > 1.0 + tolerance:
            middle = math.sqrt(low * high)
            if probe(middle):
                low = middle
            else:
                high = middle
    found = PeakRate(base.engine, grid, low, (low, high), probes, budget=budget)
    if math.isfinite(low):
        at = replace(base, rate_hz=low)
        timing = warmup(at)
        found.grid = timing.mesh or f'{timing.grid[0]}x{timing.grid[1]}'
        found.warmup_p99_s = timing.p99_s
        if lockstep:
            found.cd = lockstep_cd(replace(at, duration=0.0))
    return found
