"""
Cross-reference cells: every engine against every synthetic reference, as a sweep mode.

The bundled bags are simulations, so a score on them says how much an engine behaves like the
reference model. Scoring every engine against two references of different model families
(MuJoCo's shell, Newton's VBD) turns that bias into numbers. The cells run on the executor like
any sweep's (parallel, resumable, one results row each, with the reference it was scored against).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.studies.cells import Cell, config_label, CROSS_REFERENCE

MODE = CROSS_REFERENCE
REFERENCES = ('mujoco', 'newton-vbd')
# (engine, parameter overrides of its preset): the entrants of the table.
DEFAULT_ENTRANTS: tuple[tuple[str, dict], ...] = (
    ('mujoco', {}),
    ('bullet', {}),
    ('newton', {'model': 'vbd'}),
    ('newton', {'model': 'xpbd'}),
)


def reference_bag(cloth: str, primitive: str, reference: str) -> Path:
    """Return the bundled bag of a cloth and task made by `reference`."""
    if reference not in REFERENCES:
        raise ValueError(
            f'unknown synthetic reference {reference!r} (valid: {", ".join(REFERENCES)})'
        )
    suffix = '' if reference == 'mujoco' else '_' + reference.replace('-', '_')
    return share_dir('bags') / f'{cloth}_{primitive}{suffix}'


def cross_reference_cells(
    cloth: str = 'towel',
    primitives: Sequence[str] = ('dynamic', 'quasi_static'),
    seeds: Sequence[int] = (0, 1, 2),
    rate_hz: float = 100.0,
    entrants: Sequence[tuple[str, dict]] = DEFAULT_ENTRANTS,
    references: Sequence[str] = REFERENCES,
) -> list[Cell]:
    """One sweep cell per entrant x reference x task x seed (mode "cross_reference")."""
    cells = []
    for reference in references:
        for primitive in primitives:
            bag = reference_bag(cloth, primitive, reference)
            for (engine, overrides), seed in ((e, s) for e in entrants for s in seeds):
                label = f'reference={reference},' + config_label(None, overrides)
                cells.append(
                    Cell(
                        engine,
                        float(rate_hz),
                        cloth,
                        primitive,
                        int(seed),
                        str(bag),
                        0,
                        MODE,
                        label,
                        None,
                        tuple(sorted(overrides.items())),
                    )
                )
    return cells
