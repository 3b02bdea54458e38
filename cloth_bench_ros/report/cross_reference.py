"""
Cross-reference table: every engine's CD_d / CD_q against every synthetic reference.

An engine of the reference's own family should win on its own reference, and by how much is the
point (the cells are studies/cross_reference.py's).
"""

from __future__ import annotations

import math
from typing import Sequence

from cloth_bench_ros.report.blocks import Table
from cloth_bench_ros.report.selections import engine_label
from cloth_bench_ros.studies.aggregate import group, stat
from cloth_bench_ros.studies.cross_reference import DEFAULT_ENTRANTS, MODE, REFERENCES

REFERENCE_LABEL = {'mujoco': 'MuJoCo shell ref.', 'newton-vbd': 'Newton VBD ref.'}
NOTE = (
    'Every engine with its preset (lockstep, the rate given) scored against both synthetic'
    " references of the bundled bags: MuJoCo's flex shell (`bags/<cloth>_<task>`) and Newton's"
    ' VBD (`bags/<cloth>_<task>_newton_vbd`), both 31 x 43 vertices seen by the same virtual'
    " Kinect. Mean ± std over seeds, in metres; bold: the best in its column. A column's winner"
    ' is the engine closest to that reference model, not to real cloth; the gap between an'
    " engine's two columns is the bias a reference puts on it."
)


def entrant_name(engine: str, overrides: dict) -> str:
    """Return an entrant's name: "newton (vbd)" for a model override, else the engine's label."""
    model = overrides.get('model')
    return f'{engine_label(engine)} ({model})' if model else engine_label(engine)


def cross_reference_table(rows: Sequence[dict], digits: int = 3) -> Table | None:
    """Return entrants x (reference, task) of CD_d / CD_q; None without cross-reference rows."""
    sel = [r for r in rows if r.get('mode') == MODE and r.get('reference') in REFERENCES]
    if not sel:
        return None
    primitives = [p for p in ('dynamic', 'quasi_static') if any(r['primitive'] == p for r in sel)]
    references = [ref for ref in REFERENCES if any(r['reference'] == ref for r in sel)]
    columns = [(ref, p) for ref in references for p in primitives]
    # The default entrants' order, then any other; rows come in the order their cells finished.
    order = [(engine, overrides.get('model', '')) for engine, overrides in DEFAULT_ENTRANTS]
    found = {(r['engine'], (r.get('params') or {}).get('model', '')) for r in sel}
    entrants = sorted(found, key=lambda e: (order.index(e) if e in order else len(order), e))
    by = group(sel, 'engine', 'reference', 'primitive')
    stats = {}
    for engine, model in entrants:
        for ref, p in columns:
            cell_rows = [
                r
                for r in by.get((engine, ref, p), [])
                if (r.get('params') or {}).get('model', '') == model
            ]
            stats[(engine, model, ref, p)] = stat(cell_rows, 'CD')
    best = {
        col: min(
            (s.mean for (e, m, *c), s in stats.items() if tuple(c) == col and s.used),
            default=math.nan,
        )
        for col in columns
    }
    body = []
    for engine, model in entrants:
        line = [entrant_name(engine, {'model': model} if model else {})]
        for col in columns:
            s = stats[(engine, model) + tuple(col)]
            text = s.text(digits, show_n=False)
            line.append(
                f'**{text}**' if s.used and s.mean == best[col] and len(entrants) > 1 else text
            )
        body.append(line)
    headers = ['engine'] + [
        f'{REFERENCE_LABEL[ref]} {"CD_d" if p == "dynamic" else "CD_q"}' for ref, p in columns
    ]
    return Table('cross_reference', headers, body, 'l' + 'r' * len(columns))


def cross_reference_section(rows: Sequence[dict]) -> tuple[str, str, Table] | None:
    """Return (heading, note, table) of the cross-reference section, or None without such rows."""
    table = cross_reference_table(rows)
    if table is None:
        return None
    cloths = sorted({r['cloth'] for r in rows if r.get('mode') == MODE})
    seeds = sorted({int(r['seed']) for r in rows if r.get('mode') == MODE})
    rates = sorted({float(r['rate_hz']) for r in rows if r.get('mode') == MODE})
    heading = (
        f'Cross-reference: each engine against each synthetic reference ({", ".join(cloths)})'
    )
    note = (
        NOTE.replace('the rate given', '/'.join(f'{r:g}' for r in rates) + ' Hz')
        + f' Seeds {seeds}.'
    )
    return heading, note, table
