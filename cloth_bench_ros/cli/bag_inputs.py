"""A command's bags when it runs: a bag's first frame checked, a recording's replay options."""

from __future__ import annotations

import argparse
from contextlib import closing
from pathlib import Path

from cloth_bench_ros.cli.common import replay_params, UserError
from cloth_bench_ros.data import alignment, replay
from cloth_bench_ros.data.bag_reader import BagReader, decode_cloud


def check_bag(bag: Path, topic: str | None = None) -> None:
    """Fail early, in one line naming the bag, unless the cloud topic's first frame decodes."""
    with BagReader(bag) as reader:
        topic = reader.cloud_topic(topic)
        with closing(reader.raw_messages([topic])) as frames:  # its file is closed here
            first = next(frames, None)
        if first is None:
            raise UserError(f'bag {bag}: no PointCloud2 message on {topic} could be read')
        decode_cloud(bag, topic, 0, first[2], first[3])


def replay_options(args: argparse.Namespace, task: str = '') -> replay.ReplayOptions:
    """Return the ReplayOptions of the recording options, as the recorder node builds them."""
    p = replay_params(args)
    return replay.ReplayOptions(
        cloth=args.cloth, primitive=args.primitive, task=task or args.task or '',
        motion=p['motion'], change_of_phase_frame=args.change_of_phase_frame, topic=p['topic'],
        start_time=p['start_time'], targets_topic=p['targets_topic'],
        transform=tuple(p['transform']) if 'transform' in p else None, clean=p['clean'],
        voxel=p['voxel'], table_plane=p['table_plane'], rate_hz=float(args.rate),
        search=alignment.SearchSettings(window=p['align_window'], coarse_step=p['align_step']),
        trial=p['trial'], align=p['align'],
    )
