"""The parser of `cloth-bench rank`: which simulator for my cloth, from the user's recordings."""

from __future__ import annotations

import argparse

from cloth_bench_ros.cli import common
from cloth_bench_ros.cli.identify import TRIALS
from cloth_bench_ros.engines import engine_class

RESULT_FILE = 'rank.json'


def _entrant(text: str, label: str = '--engine') -> tuple[str, dict]:
    """--engine NAME or NAME:MODEL (newton:xpbd, newton:vbd)."""
    name, _, model = text.strip().partition(':')
    engine_class(name)  # EngineError, one line, for an unknown engine
    return name, ({'model': model} if model else {})


RANK_FLAGS: tuple[common.Flag, ...] = (
    'recordings',
    ('engines', {'validate': _entrant,
                 'help': 'engine[:model] (repeat; default mujoco, bullet, newton:xpbd)'}),
    TRIALS,
    'sampler',
    ('fidelity', {'help': 'identification: full (default), or prune, coarse: multi-fidelity, '
                  'as identify'}),
    'rank_seeds',
    ('rate_hz', {'help': 'simulator rate of identification and scoring'}),
    'rates',
    'grid',
    'metric',  # cd/hd: also the identification objective (else cd)
    'max_frames',
    'settle',
    ('output', {'help': 'directory (default results/rank)'}),
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register rank."""
    rank = sub.add_parser(
        'rank',
        parents=[common.scene_options(), common.executor_options()],
        help='rank the engines on your own recordings: identified, scored on held-out trials',
    )
    common.add_options(rank, RANK_FLAGS)
    common.add_renamed(rank, '--rates', '--recommend-rate', split=True)
    common.recording_options(rank)
    common.engine_override_option(rank, 'fixed on every entrant of that engine, not fitted')
    common.add_option(rank, 'cloth_size')
    common.add_option(rank, 'cloth_mass', help='total mass of the cloth, not fitted')
    common.add_option(rank, 'cloth_mesh')
    rank.set_defaults(implementation='cloth_bench_ros.cli.rank_command:cmd_rank')
