"""The parser of `cloth-bench hil`: hardware in the loop, the simulator in its own process."""

from __future__ import annotations

import argparse

from cloth_bench_ros.cli import common
from cloth_bench_ros.cli.studies import tolerance_options


HIL_FLAGS: tuple[common.Flag, ...] = (
    ('engines', {'help': 'engine[:model] (repeat for several; default mujoco)'}),
    ('rate_list', {'help': 'simulator rate (repeat for several; default 100)'}),
    'hil_config',
    'settings',
    'budget',
    'bag',
    'seed',
    ('grid', {'action': 'append', 'help': "cloth mesh NXxNZ (default: the engine's; several "
              'with --find-rate)'}),
)
LAYOUT_FLAGS: tuple[common.Flag, ...] = (
    'layout',
    'cpu',
    'fifo',
    'no_freeze_gc',
    'busy_wait',
    'in_process',
    'duration',
    'no_lockstep',
    ('output', {'help': 'results directory (default results/hil)'}),
    'export_recommended',
    'note',
)

FIND_RATE_FLAGS: tuple[common.Flag, ...] = (
    'find_rate', 'miss_threshold', 'rate_min', 'rate_max', 'rate_tolerance', 'repeats',
)


def find_rate_options(hil: argparse.ArgumentParser) -> None:
    """Register --find-rate and its options, and the miss threshold."""
    common.add_options(hil, FIND_RATE_FLAGS)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register hil."""
    hil = sub.add_parser(
        'hil',
        parents=[
            common.scene_options(),
            tolerance_options(),
            common.presets_options(),
            common.live_options(),
        ],
        help='hardware in the loop: targets on the wall clock, the simulator in its own process',
    )
    common.add_options(hil, HIL_FLAGS)
    common.engine_override_option(hil, 'engine parameter override')
    common.add_options(hil, LAYOUT_FLAGS)
    find_rate_options(hil)
    common.add_option(hil, 'task')
    common.add_option(hil, 'cloth_mesh')
    hil.set_defaults(implementation='cloth_bench_ros.cli.hil_command:cmd_hil')
