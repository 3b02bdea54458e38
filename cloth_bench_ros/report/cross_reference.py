"""Cross-reference table: every engine's CD_d / CD_q against every synthetic reference.

The bundled bags are simulations, so a score on them says how much an engine behaves like the
reference model. Scoring every engine against two references of different model families
(MuJoCo's shell, Newton's VBD) turns that bias into numbers: an engine of the reference's own
family should win on its own reference, and by how much is the point.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, Sequence

from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.report.blocks import Table
from cloth_bench_ros.report.statistics import engine_label, group, stat
from cloth_bench_ros.studies.sweep import Cell, config_label

MODE = "cross_reference"
REFERENCES = ("mujoco", "newton-vbd")
REFERENCE_LABEL = {"mujoco": "MuJoCo shell ref.", "newton-vbd": "Newton VBD ref."}
# (engine, parameter overrides of its preset): the entrants of the table.
DEFAULT_ENTRANTS: tuple[tuple[str, dict], ...] = (
    ("mujoco", {}), ("bullet", {}), ("newton", {"model": "vbd"}), ("newton", {"model": "xpbd"}),
)
NOTE = (
    "Every engine with its preset (lockstep, the rate given) scored against both synthetic references "
    "of the bundled bags: MuJoCo's flex shell (`bags/<cloth>_<task>`) and Newton's VBD "
    "(`bags/<cloth>_<task>_newton_vbd`), both 31 x 43 vertices seen by the same virtual Kinect. "
    "Mean ± std over seeds, in metres; bold: the best in its column. A column's winner is the "
    "engine closest to that reference model, not to real cloth; the gap between an engine's two "
    "columns is the bias a reference puts on it."
)


def reference_bag(cloth: str, primitive: str, reference: str) -> Path:
    """The bundled bag of a cloth and task made by `reference`."""
    if reference not in REFERENCES:
        raise ValueError(f"unknown synthetic reference {reference!r} (valid: {', '.join(REFERENCES)})")
    suffix = "" if reference == "mujoco" else "_" + reference.replace("-", "_")
    return share_dir("bags") / f"{cloth}_{primitive}{suffix}"


def entrant_name(engine: str, overrides: dict) -> str:
    """An entrant's name: "newton (vbd)" for an engine with a model override, else the engine's label."""
    model = overrides.get("model")
    return f"{engine_label(engine)} ({model})" if model else engine_label(engine)


def cross_reference_cells(cloth: str = "towel", primitives: Sequence[str] = ("dynamic", "quasi_static"),
                          seeds: Sequence[int] = (0, 1, 2), rate_hz: float = 100.0,
                          entrants: Sequence[tuple[str, dict]] = DEFAULT_ENTRANTS,
                          references: Sequence[str] = REFERENCES) -> list[Cell]:
    """One sweep cell per entrant x reference x task x seed (mode "cross_reference")."""
    cells = []
    for reference in references:
        for primitive in primitives:
            bag = reference_bag(cloth, primitive, reference)
            for (engine, overrides), seed in ((e, s) for e in entrants for s in seeds):
                label = f"reference={reference}," + config_label(None, overrides)
                cells.append(Cell(engine, float(rate_hz), cloth, primitive, int(seed), str(bag), 0, MODE,
                                  label, None, tuple(sorted(overrides.items()))))
    return cells


def run_cross_reference(cells: Sequence[Cell], out_dir: Path,
                        on_row: Callable[[dict], None] | None = None) -> list[dict]:
    """Run the cells one after the other in this process; the results rows (with `reference`)."""
    from cloth_bench_ros.studies.sweep import run_cell

    rows = []
    for cell in cells:
        row = run_cell(cell, str(out_dir))
        row["reference"] = cell.config.split(",")[0].removeprefix("reference=")
        rows.append(row)
        if on_row is not None:
            on_row(row)
    return rows


def cross_reference_table(rows: Sequence[dict], digits: int = 3) -> Table | None:
    """Entrants x (reference, task) of CD_d / CD_q; None when `rows` has no cross-reference rows."""
    sel = [r for r in rows if r.get("mode") == MODE and r.get("reference") in REFERENCES]
    if not sel:
        return None
    primitives = [p for p in ("dynamic", "quasi_static") if any(r["primitive"] == p for r in sel)]
    references = [ref for ref in REFERENCES if any(r["reference"] == ref for r in sel)]
    columns = [(ref, p) for ref in references for p in primitives]
    entrants: list[tuple[str, str]] = []
    for r in sel:
        key = (r["engine"], (r.get("params") or {}).get("model", ""))
        if key not in entrants:
            entrants.append(key)
    by = group(sel, "engine", "reference", "primitive")
    stats = {}
    for engine, model in entrants:
        for ref, p in columns:
            cell_rows = [r for r in by.get((engine, ref, p), []) if (r.get("params") or {}).get("model", "") == model]
            stats[(engine, model, ref, p)] = stat(cell_rows, "CD")
    best = {col: min((s.mean for (e, m, *c), s in stats.items() if tuple(c) == col and s.used),
                     default=math.nan) for col in columns}
    body = []
    for engine, model in entrants:
        line = [entrant_name(engine, {"model": model} if model else {})]
        for col in columns:
            s = stats[(engine, model, *col)]
            text = s.text(digits, show_n=False)
            line.append(f"**{text}**" if s.used and s.mean == best[col] and len(entrants) > 1 else text)
        body.append(line)
    headers = ["engine"] + [f"{REFERENCE_LABEL[ref]} {'CD_d' if p == 'dynamic' else 'CD_q'}" for ref, p in columns]
    return Table("cross_reference", headers, body, "l" + "r" * len(columns))


def cross_reference_section(rows: Sequence[dict]) -> tuple[str, str, Table] | None:
    """(heading, note, table) of the report's cross-reference section, or None without such rows."""
    table = cross_reference_table(rows)
    if table is None:
        return None
    cloths = sorted({r["cloth"] for r in rows if r.get("mode") == MODE})
    seeds = sorted({int(r["seed"]) for r in rows if r.get("mode") == MODE})
    rates = sorted({float(r["rate_hz"]) for r in rows if r.get("mode") == MODE})
    heading = f"Cross-reference: each engine against each synthetic reference ({', '.join(cloths)})"
    note = NOTE.replace("the rate given", "/".join(f"{r:g}" for r in rates) + " Hz") + f" Seeds {seeds}."
    return heading, note, table
