"""
The metrics a ranking or comparison can be made on (`--metric`), declared once (docs/metrics.md).

Each has its name on the command line, the key of its task-window value in a run's summary
(per engine; `_d` / `_q` appended for a per-task metric), whether more is better, and its unit.
`metric(name)` is the validated choice; `Metric.value(summary, primitive)` reads an engine's value
in a run's summary, `Metric.row_value(row)` a study row's (the row holds the task's value under
`key`), and `Metric.sort_key` orders values best first, a missing (NaN) value last.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from cloth_bench_ros.validation import InputError

DEFAULT_METRIC = 'cd'


@dataclass(frozen=True)
class Metric:
    """One rankable metric."""

    name: str  # as given to --metric
    key: str  # summary key stem
    label: str
    unit: str
    higher_is_better: bool = False
    per_task: bool = True  # the summary holds key_d (dynamic) or key_q (quasi-static)
    absolute: bool = False  # ranked on the magnitude (a signed error)

    def summary_key(self, primitive: str) -> str:
        """Return the engine summary's key of this metric for a task."""
        if not self.per_task:
            return self.key
        return f'{self.key}_{"d" if primitive == "dynamic" else "q"}'

    def value(self, engine_summary: dict, primitive: str) -> float:
        """Return an engine's value of this metric (NaN when missing)."""
        v = engine_summary.get(self.summary_key(primitive))
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan

    def row_value(self, row: dict) -> float:
        """Return a study results row's value of this metric (its task's; NaN when missing)."""
        v = row.get(self.key)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan

    def ranked(self, value: float | None) -> float | None:
        """Return the value a ranking orders lowest first (negated if more is better, |error|)."""
        if value is None or not math.isfinite(value):
            return None
        if self.absolute:
            return abs(value)
        return -value if self.higher_is_better else value

    def sort_key(self, value: float | None) -> float:
        """Return a key that orders values best first (missing or NaN last)."""
        if value is None or not math.isfinite(value):
            return math.inf
        if self.absolute:
            return abs(value)
        return -value if self.higher_is_better else value


METRICS: dict[str, Metric] = {
    m.name: m
    for m in (
        Metric('cd', 'CD', 'CD (paper: vertices -> real)', 'm'),
        Metric('hd', 'HD', 'HD (paper: vertices -> real)', 'm'),
        Metric('cd_reverse', 'CD_reverse', 'CD real -> surface', 'm'),
        Metric('hd_reverse', 'HD_reverse', 'HD real -> surface', 'm'),
        Metric('cd_surface', 'CD_surface', 'CD surface -> real', 'm'),
        Metric('hd_surface', 'HD_surface', 'HD surface -> real', 'm'),
        Metric('cd_two_sided', 'CD_two_sided', 'two-sided CD', 'm'),
        Metric('hd_two_sided', 'HD_two_sided', 'two-sided HD', 'm'),
        Metric('precision', 'precision', 'precision', '', higher_is_better=True),
        Metric('recall', 'recall', 'recall', '', higher_is_better=True),
        Metric('fscore', 'F', 'F-score', '', higher_is_better=True),
        Metric('emd', 'EMD', 'EMD (optimal transport)', 'm'),
        Metric(
            'contact_onset',
            'contact_onset_error_s',
            'contact-onset error',
            's',
            per_task=False,
            absolute=True,
        ),
    )
}


def metric(name: object, option: str = '--metric') -> Metric:
    """Return the metric called `name`; an unknown one is refused with the valid names."""
    if isinstance(name, Metric):
        return name
    found = METRICS.get(str(name).strip().lower())
    if found is None:
        raise InputError(f'{option}: unknown metric {name!r} (valid: {", ".join(METRICS)})')
    return found
