"""The parsers of `cloth-bench import`, `synth`, `converge` and `bag` (run in data_command)."""

from __future__ import annotations

import argparse

from cloth_bench_ros.cli import common


IMPORT_FLAGS: tuple[common.Flag, ...] = (
    'root',
    ('output', {'help': 'directory for the bags (required)'}),
    ('transform', {'help': '4x4 matrix into the simulation frame (text file of 16 numbers, or '
                   '.npy)'}),
    ('overwrite', {'help': 'replace bags that exist'}),
    'import_clean',
    ('voxel', {'help': 'with --clean: voxel size (0: off)'}),
    'no_progress',
)
SYNTH_FLAGS: tuple[common.Flag, ...] = (
    ('output', {'help': 'bag directory (default <cloth>_<primitive>[_newton_vbd])'}),
    ('seed', {'help': 'sensor noise and reference seed'}),
    'reference',
    'synth_rate',
    ('overwrite', {'help': 'replace the bag if it exists'}),
    'no_progress',
)
CONVERGE_FLAGS: tuple[common.Flag, ...] = (
    ('reference', {'help': 'the reference model'}),
    'converge_axis',
    'levels',
    'converge_duration',
    'score',
    ('output', {'help': 'directory: one .npz per run (reused) and convergence.json (default '
                'results/convergence/<reference>_<cloth>_<primitive>)'}),
)
REWRITE_FLAGS: tuple[common.Flag, ...] = ('src', 'dst', 'rewrite_change_of_phase_frame')


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register import, synth, converge and bag (info, rewrite)."""
    imp = sub.add_parser(
        'import', help='turn the published dataset (PLY/PCD per frame) into one bag per trial'
    )
    common.add_options(imp, IMPORT_FLAGS)
    common.add_renamed(imp, '--out', '--output')
    common.add_renamed(imp, '--quiet', '--no-progress')
    imp.set_defaults(implementation='cloth_bench_ros.cli.data_command:cmd_import')

    synth = sub.add_parser(
        'synth',
        parents=[common.scene_options()],
        help='make a synthetic reference bag (reference simulation seen by a virtual Kinect)',
    )
    common.add_options(synth, SYNTH_FLAGS)
    common.add_renamed(synth, '--out', '--output')
    common.add_renamed(synth, '--quiet', '--no-progress')
    common.device_option(synth, with_set=False)
    synth.set_defaults(implementation='cloth_bench_ros.cli.data_command:cmd_synth')

    converge = sub.add_parser(
        'converge',
        parents=[common.scene_options(), common.executor_options()],
        help="a synthetic reference's convergence in iterations, step rate and mesh resolution",
    )
    common.add_options(converge, CONVERGE_FLAGS)
    common.device_option(converge, with_set=False)
    converge.set_defaults(implementation='cloth_bench_ros.cli.data_command:cmd_converge')

    bag = sub.add_parser('bag', help='bag tools')
    bag_sub = bag.add_subparsers(dest='bag_command', required=True, parser_class=common.Parser)
    info = bag_sub.add_parser('info', help='describe a bag: topics, frames, trial metadata')
    common.add_option(info, 'path')
    info.set_defaults(implementation='cloth_bench_ros.cli.data_command:cmd_bag_info')
    rewrite = bag_sub.add_parser(
        'rewrite',
        help=(
            "copy a bag into the current writer's layout (rosbag2 Jazzy, "
            'metadata version 9, type hashes); messages and trial unchanged'
        ),
    )
    common.add_options(rewrite, REWRITE_FLAGS)
    rewrite.set_defaults(implementation='cloth_bench_ros.cli.data_command:cmd_bag_rewrite')
