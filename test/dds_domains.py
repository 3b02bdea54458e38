"""Random ROS domains that pytest-xdist workers never share (the suite runs in two processes)."""

import os
import random


def random_domain(highest: int = 200) -> int:
    """Return a random domain in 1..highest from worker i of n's share: i+1, i+1+n, ..."""
    worker = int(os.environ.get('PYTEST_XDIST_WORKER', 'gw0').removeprefix('gw'))
    workers = int(os.environ.get('PYTEST_XDIST_WORKER_COUNT', '1'))
    return random.randrange(1 + worker, highest + 1, workers)
