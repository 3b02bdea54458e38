"""The parser of `cloth-bench identify`: fit an engine's cloth parameters to a bag."""

from __future__ import annotations

import argparse

from cloth_bench_ros import options, validation
from cloth_bench_ros.cli import common
from cloth_bench_ros.identify.spec import AUTO


def trials_value(text: str, label: str = '--trials') -> int:
    """--trials: a count >= 1, or auto (the study's AUTO)."""
    if text.strip().lower() == 'auto':
        return AUTO
    try:
        return validation.integer(validation.parse_integer(text, label), label, 1)
    except validation.InputError as exc:
        raise validation.InputError(f'{exc} (or auto)') from None


TRIALS = options.declared('trials').variant(validate=trials_value)
IDENTIFY_FLAGS: tuple[common.Flag, ...] = (
    ('engine', {'help': 'the engine to fit, or engine:model (e.g. newton:vbd)'}),
    ('bag', {'help': 'rosbag2 bag to fit (default: the bundled one)'}),
    'sampler',
    TRIALS,
    'fidelity',
    'objective',
    'params',
    ('seed', {'help': 'seed of every trial'}),
    'rate_hz',
    'grid',
)
FIT_FLAGS: tuple[common.Flag, ...] = (
    'span',
    ('max_frames', {'help': 'score only the first N frames of the window (faster)'}),
    'batch',
    'validate_seeds',
    'validation_bag_dir',
    'settle',
    ('output', {'help': 'directory (default results/identify/<engine>_<cloth>_<primitive>)'}),
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register identify."""
    ident = sub.add_parser(
        'identify',
        parents=[common.scene_options(), common.executor_options()],
        help="fit an engine's cloth parameters to a bag (CMA-ES and Bayesian optimisation)",
    )
    common.add_options(ident, IDENTIFY_FLAGS)
    common.add_renamed(ident, '--params', '--param', split=True)
    common.engine_override_option(ident, 'fixed override, not fitted')
    common.add_options(ident, FIT_FLAGS)
    # a plain recording is split as rank splits it: its first usable trial (--trial N) is fitted
    common.recording_options(ident)
    common.add_option(ident, 'cloth_size')
    common.add_option(ident, 'cloth_mass', help='total mass of the cloth, not fitted unless '
                      "--param names mass (unset: the preset's mass per area times the area)")
    common.add_option(ident, 'cloth_mesh')
    ident.set_defaults(implementation='cloth_bench_ros.cli.identify_command:cmd_identify')
