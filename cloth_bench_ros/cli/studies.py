"""The parsers of `sweep`, `report`, `stress` and `cross-reference` (run in studies_command)."""

from __future__ import annotations

import argparse

from cloth_bench_ros.cli import common
from cloth_bench_ros.options import FLAGS, OPTIONS

TOLERANCE_REL = FLAGS['tolerance_rel'].default  # settings recommendation: CD within this ...
TOLERANCE_ABS = FLAGS['tolerance_abs'].default  # ... fraction of the best, or these metres

SWEEP_FLAGS: tuple[common.Flag, ...] = (
    'sweep_mode',
    ('engines', {'help': 'engine[:model] (repeat for several; default: mujoco, bullet, newton)'}),
    ('rate_list', {'help': 'simulator rate (repeat for several; default 10, 100, 1000; settings '
                   'mode: one rate, default 100)'}),
    ('cloth_list', {'help': 'the cloth (repeat; default all three; settings mode: towel)'}),
    ('primitive_list', {'help': 'the task (repeat; default both)'}),
    ('seeds', {'help': 'number of seeds (default 20; settings mode 2)'}),
    'seed_start',
    ('output', {'help': 'results directory (default results/sweep or results/settings)'}),
    'sweep_bag_dir',
    ('grid', {'help': 'cloth mesh NXxNZ for every cell (paper mode)'}),
)
SWEEP_RUN_FLAGS: tuple[common.Flag, ...] = (
    'pacing',
    'settle',
    'step_per_target',
    'keep_frames',
    'sweep_axis',
    'retry_errors',
    'all_metrics',
    'dry_run',
    'report',
    'metric',
)
REPORT_FLAGS: tuple[common.Flag, ...] = (
    'results',
    ('output', {'help': 'report directory (default <results dir>/report)'}),
    'stress',
    ('rate_hz', {'help': 'rate of the Table III layout'}),
    OPTIONS['cloth'].variant(flag='--fig5-cloth', help='cloth of the Fig. 5 layout'),
    'metric',
)
ENGINES = ('engines', {'help': 'repeat for several (default: mujoco, bullet, newton)',
                       'metavar': 'ENGINE'})  # names only: stress has no --set for a model
STRESS_FLAGS: tuple[common.Flag, ...] = (
    ENGINES,
    'case',
    'list',
    'max_wall_s',
    ('output', {'help': 'results directory (default results/stress)'}),
)
XREF_FLAGS: tuple[common.Flag, ...] = (
    ('cloth', {'help': 'the cloth; needs its <cloth>_<task>_newton_vbd bags'}),
    ('primitive_list', {'help': 'the task (repeat; default both)'}),
    'xref_seeds',
    'xref_seed_start',
    'rate_hz',
    'xref_output',
    'metric',
)


def tolerance_options() -> argparse.ArgumentParser:
    """Parent parser: the settings recommendation's CD tolerance."""
    parent = argparse.ArgumentParser(add_help=False)
    common.add_options(parent, ('tolerance_rel', 'tolerance_abs'))
    return parent


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register sweep, report, stress and cross-reference."""
    executor = common.executor_options()
    sweep = sub.add_parser(
        'sweep',
        parents=[executor, common.presets_options()],
        help='many runs in parallel: engines x rates x cloths x tasks x seeds',
    )
    common.add_options(sweep, SWEEP_FLAGS)
    common.engine_override_option(sweep, 'engine parameter override for every cell (repeatable)')
    common.add_options(sweep, SWEEP_RUN_FLAGS)
    common.add_option(sweep, 'task')
    common.add_option(sweep, 'cloth_mesh')
    sweep.set_defaults(implementation='cloth_bench_ros.cli.studies_command:cmd_sweep')

    report = sub.add_parser(
        'report',
        parents=[tolerance_options()],
        help="render a sweep's tables, plots and Markdown/HTML report",
    )
    common.add_options(report, REPORT_FLAGS)
    report.set_defaults(implementation='cloth_bench_ros.cli.studies_command:cmd_report')

    stress = sub.add_parser(
        'stress',
        parents=[executor, common.presets_options()],
        help='run the suite of hard cases; reports divergence, never fails',
    )
    common.add_options(stress, STRESS_FLAGS)
    common.device_option(stress, with_set=False)
    common.add_option(stress, 'task')
    common.add_option(stress, 'cloth_mesh')
    stress.set_defaults(implementation='cloth_bench_ros.cli.studies_command:cmd_stress')

    xref = sub.add_parser(
        'cross-reference',
        parents=[executor],
        help='score every engine against both synthetic references',
    )
    common.add_options(xref, XREF_FLAGS)
    common.device_option(xref, with_set=False)
    xref.set_defaults(implementation='cloth_bench_ros.cli.studies_command:cmd_cross_reference')
