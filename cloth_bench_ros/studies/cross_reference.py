"""
Cross-reference cells: every engine against every synthetic reference, as a sweep mode.

The bundled bags are simulations, so a score on them says how much an engine behaves like the
reference model. Scoring every engine against two references of different model families
(MuJoCo's shell, Newton's VBD) turns that bias into numbers. Each engine runs with its shipped
preset and, where one exists, with the parameters identified against the same reference (the set
`identified` or `identified-newton-vbd`): only identified engines compare fairly. The cells run
on the executor like any sweep's (parallel, resumable, one results row each, with the reference
and the preset set).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from cloth_bench_ros.command_options import REFERENCES
from cloth_bench_ros.engines.base import EngineError
from cloth_bench_ros.engines.presets import identified_set_of, load_preset, preset_set
from cloth_bench_ros.errors import InputError
from cloth_bench_ros.options import OPTIONS
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.studies.cells import Cell, config_label, CROSS_REFERENCE, set_label

MODE = CROSS_REFERENCE
KINDS = ('preset', 'identified')
SEED_START = 1  # the identifications ran on seed 0: every cross-reference seed is held out
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
        raise InputError(
            f'unknown synthetic reference {reference!r} (valid: {", ".join(REFERENCES)})'
        )
    suffix = '' if reference == 'mujoco' else '_' + reference.replace('-', '_')
    return share_dir('bags') / f'{cloth}_{primitive}{suffix}'


def identified_values(
    engine: str, overrides: dict, cloth: str, primitive: str, reference: str
) -> dict | None:
    """
    Return an entrant's parameters identified against `reference`, or None if there are none.

    None too when the set has no entry of the entrant's model (Newton XPBD values do not stand
    for Newton VBD).
    """
    try:
        directory = preset_set(identified_set_of(reference)).directory
        values = load_preset(engine, cloth, primitive, directory, overrides.get('model'))
    except EngineError:
        return None
    return {**values, **overrides}


def cross_reference_cells(
    cloth: str = OPTIONS['cloth'].default,
    primitives: Sequence[str] = ('dynamic', 'quasi_static'),
    seeds: Sequence[int] = tuple(range(SEED_START, SEED_START + 5)),
    rate_hz: float = OPTIONS['rate_hz'].default,
    entrants: Sequence[tuple[str, dict]] = DEFAULT_ENTRANTS,
    references: Sequence[str] = REFERENCES,
    kinds: Sequence[str] = KINDS,
    all_metrics: bool = False,
) -> tuple[list[Cell], list[str]]:
    """
    One sweep cell per entrant x kind x reference x task x seed (mode "cross_reference").

    Returns the cells and one line per identified entrant that has no identified parameters.
    all_metrics: score every metric, for a --metric beside the paper's CD/HD.
    """
    cells, missing = [], []
    for reference in references:
        for primitive in primitives:
            bag = reference_bag(cloth, primitive, reference)
            for (engine, overrides), kind in ((e, k) for e in entrants for k in kinds):
                label = config_label(None, overrides)
                params: dict | None = overrides
                if kind == 'identified':
                    params = identified_values(engine, overrides, cloth, primitive, reference)
                    name = identified_set_of(reference)
                    label = set_label(preset_set(name), label)
                    if params is None:
                        model = f' ({overrides["model"]})' if 'model' in overrides else ''
                        missing.append(f'{engine}{model}: no {name} preset, {cloth} {primitive}')
                        continue
                assert params is not None
                for seed in seeds:
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
                            f'reference={reference},{label}',
                            None,
                            tuple(sorted(params.items())),
                            all_metrics=all_metrics,
                        )
                    )
    return cells, missing
