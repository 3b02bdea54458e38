"""The result table of one run that the CLI prints (the run's files are core/run_files.py's)."""

from __future__ import annotations

import math


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    return f'{value:.{digits}f}'


def result_table(summary: dict, realtime: bool = False) -> str:
    """One row per engine: CD, HD, L_s and step time (ms); realtime: latency, misses, skips."""
    suffix = 'd' if summary['run']['primitive'] == 'dynamic' else 'q'
    header = (
        f'{"engine":<10} {"CD_" + suffix:>8} {"HD_" + suffix:>8} {"L_s":>10} '
        f'{"step mean":>10} {"p50":>8} {"p99":>8} {"max":>8}  status'
    )
    lines = [header, '-' * len(header)]
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
