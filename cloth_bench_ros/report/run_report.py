"""The result table of one run that the CLI prints (the run's files are core/run_files.py's)."""

from __future__ import annotations

import math

from cloth_bench_ros.core.run_summary import inputs_line
from cloth_bench_ros.metric_choice import METRICS

# the metrics beside the paper's, in the order of docs/metrics.md: (name, column title, digits)
SURFACE_COLUMNS = (
    ('cd_reverse', 'CD rev', 4),
    ('hd_reverse', 'HD rev', 4),
    ('cd_surface', 'CD surf', 4),
    ('hd_surface', 'HD surf', 4),
    ('cd_two_sided', 'CD 2s', 4),
    ('hd_two_sided', 'HD 2s', 4),
    ('precision', 'P', 3),
    ('recall', 'R', 3),
    ('fscore', 'F', 3),
    ('emd', 'EMD', 4),
    ('contact_onset', 'onset s', 3),
)


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    return f'{value:.{digits}f}'


def result_table(summary: dict, realtime: bool = False) -> str:
    """
    One row per engine: CD, HD, L_s and step time (ms); realtime: latency, misses, skips.

    Headed by `inputs_line` when the run had a task file, a recorded motion or a mesh.
    """
    suffix = 'd' if summary['run']['primitive'] == 'dynamic' else 'q'
    header = (
        f'{"engine":<10} {"CD_" + suffix:>8} {"HD_" + suffix:>8} {"L_s":>10} '
        f'{"step mean":>10} {"p50":>8} {"p99":>8} {"max":>8}  status'
    )
    inputs = inputs_line(summary)
    lines = ([inputs] if inputs else []) + [header, '-' * len(header)]
    for engine, m in summary['engines'].items():
        st = m['step_time']
        ms = {k: st[k] * 1e3 if st[k] is not None else None for k in ('mean', 'p50', 'p99', 'max')}
        status = f'diverged at step {m["diverged_at_step"]}' if m['diverged'] else 'ok'
        lines.append(
            f'{engine:<10} {_fmt(m["CD_" + suffix]):>8} {_fmt(m["HD_" + suffix]):>8}'
            f' {_fmt(m["L_s"], 7):>10} {_fmt(ms["mean"], 3):>10} {_fmt(ms["p50"], 3):>8}'
            f' {_fmt(ms["p99"], 3):>8} {_fmt(ms["max"], 3):>8}  {status}'
        )
    lines.append('CD/HD in m (one-sided, L1); L_s in m; step times in ms.')
    lines.extend(surface_table(summary))
    for engine, m in summary['engines'].items() if realtime else ():
        lat = m.get('latency') or {}
        if lat.get('count'):  # targets on the wall clock: deadlines mean something
            lines.append(
                f'{engine} real time: latency p50 {_fmt(lat["p50"] * 1e3, 3)} ms, p99'
                f' {_fmt(lat["p99"] * 1e3, 3)} ms; {m.get("deadline_misses")} of {lat["count"]}'
                f' states late (deadline 1/rate); {m.get("skipped_targets", 0)} targets skipped'
                ' (a newer one was waiting)'
            )
    return '\n'.join(lines)


def surface_table(summary: dict) -> list[str]:
    """Lines of the metrics beside the paper's per engine (none when they were not computed)."""
    primitive = summary['run']['primitive']
    engines = summary['engines']
    if not any(METRICS['cd_reverse'].summary_key(primitive) in m for m in engines.values()):
        return []
    header = f'{"engine":<10}' + ''.join(f' {title:>8}' for _, title, _ in SURFACE_COLUMNS)
    lines = ['', header, '-' * len(header)]
    for engine, m in engines.items():
        cells = ''.join(
            f' {_fmt(METRICS[name].value(m, primitive), digits):>8}'
            for name, _, digits in SURFACE_COLUMNS
        )
        lines.append(f'{engine:<10}{cells}')
    lines.append(
        "beside the paper's (docs/metrics.md): rev = real points -> simulated surface (CD rev"
        f' and R on {_setting(engines, "reverse_samples")} real points spread over the frame,'
        ' HD rev on all), surf = surface samples -> real points, 2s = two-sided; P/R/F at'
        f' {_threshold(engines) * 100:g} cm; EMD on'
        f' {_setting(engines, "ot_samples")} + {_setting(engines, "ot_samples")} points spread'
        ' over each (its floor: a sheet that matches exactly scores 0.05-0.09 m);'
        ' onset = simulated - real contact time (s, dynamic; - when either never touches).'
    )
    return lines


def _setting(engines: dict, key: str) -> object:
    for m in engines.values():
        if key in (m.get('surface_metrics') or {}):
            return m['surface_metrics'][key]
    return '-'


def _threshold(engines: dict) -> float:
    value = _setting(engines, 'fscore_threshold_m')
    return float(value) if isinstance(value, (int, float)) else math.nan
