"""The parsers of `cloth-bench run`, `trajectory`, `motion` and `engines` (run in run_command)."""

from __future__ import annotations

import argparse

from cloth_bench_ros.cli import common
from cloth_bench_ros.options import MOTION_FLAGS


RUN_FLAGS: tuple[common.Flag, ...] = (
    ('engines', {'help': 'engine[:model] to run (repeat for several; default mujoco)'}),
    'rate_hz',
    ('bag', {'help': 'rosbag2 bag to score against (default: the bundled one)'}),
    'seed',
    'pacing',
    'processes',
    ('output', {
        'help': 'report directory (default results/<cloth>_<primitive>_<rate>hz_seed<seed>)'
    }),
)
# the run's own outputs of a recording (the recording options: common.recording_options)
SCORING_FLAGS: tuple[common.Flag, ...] = (
    'record_comparison',
    'figures',
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register run, trajectory and engines."""
    run = sub.add_parser(
        'run',
        parents=[common.scene_options(), common.presets_options(), common.live_options()],
        help='run the node graph on a bag and print the result table',
    )
    common.add_options(run, RUN_FLAGS)
    common.add_options(common.recording_options(run), SCORING_FLAGS)
    common.add_option(run, 'grid')
    common.engine_override_option(
        run, 'override an engine parameter on top of the preset (repeatable)'
    )
    common.add_option(run, 'cloth_size')
    common.add_option(run, 'cloth_mass')
    common.add_option(run, 'cloth_mesh')
    run.set_defaults(implementation='cloth_bench_ros.cli.run_command:cmd_run')

    traj = sub.add_parser('trajectory', help="print a task's motion as CSV")
    common.add_options(traj, ('primitive', 'task', 'rate_hz'))
    traj.set_defaults(implementation='cloth_bench_ros.cli.run_command:cmd_trajectory')

    motion = sub.add_parser(
        'motion', help="write a recording's gripper motion as a task file (for --task, task:=)"
    )
    common.add_options(motion, (
        ('bag', {'help': 'rosbag2 recording', 'required': True}), 'topic', *MOTION_FLAGS,
        'targets_topic', ('output', {'help': 'the task file to write', 'metavar': 'FILE',
                                     'required': True}),
    ))
    motion.set_defaults(implementation='cloth_bench_ros.cli.run_command:cmd_motion')

    engines = sub.add_parser('engines', help='list known engines, their availability and version')
    common.add_option(engines, 'warm')
    engines.set_defaults(implementation='cloth_bench_ros.cli.run_command:cmd_engines')
