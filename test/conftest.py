"""Fixtures shared by the tests: small real MCAP bags made on the spot."""

from __future__ import annotations

import os
from pathlib import Path
import random

from bag_fixtures import write_hanging_cloth_bag
import pytest


@pytest.fixture(scope='session')
def hanging_bag(tmp_path_factory) -> Path:
    return write_hanging_cloth_bag(tmp_path_factory.mktemp('bags') / 'hanging')


@pytest.fixture(scope='session', autouse=True)
def dds_on_loopback():
    """
    Every DDS participant of the run (here and in the node processes tests start) on loopback.

    Interface lo, no multicast, peer 127.0.0.1, on a random ROS domain so parallel runs stay apart.
    """
    from cloth_bench_ros.runtime.dds import loopback_environment

    entries = {
        **loopback_environment(random.randint(1, 200)),
        'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST',
    }
    saved = {key: os.environ.get(key) for key in [*entries, 'ROS_STATIC_PEERS']}
    os.environ.update(entries)
    os.environ.pop('ROS_STATIC_PEERS', None)
    yield entries
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
