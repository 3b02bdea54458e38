"""Shared fixtures: small real bags made on the spot, DDS on loopback, one Dask cluster."""

from __future__ import annotations

from collections.abc import Callable, Iterator
import contextlib
import os
from pathlib import Path

from bag_fixtures import write_hanging_cloth_bag
from dds_domains import random_domain
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
        **loopback_environment(random_domain()),
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


@pytest.fixture(scope='session')
def dask_cluster_address(tmp_path_factory) -> Iterator[Callable[[], str]]:
    """
    Return a function giving the session's one Dask LocalCluster address, started on first call.

    The cluster is the one a study starts (cloth_bench_ros.studies.dask_executor.open_client:
    worker processes on 127.0.0.1), kept for the whole session; its workers write to workers.log.
    """
    from cloth_bench_ros.studies import dask_executor

    start_cluster = dask_executor._cluster_client  # before any test points it here
    with contextlib.ExitStack() as stack:
        addresses: list[str] = []

        def address() -> str:
            if not addresses:
                log = tmp_path_factory.mktemp('dask') / 'workers.log'
                plugin = dask_executor._WorkerSetup(str(log), local=True)
                client = stack.enter_context(start_cluster(None, None, plugin))
                addresses.append(client.scheduler.address)
            return addresses[0]

        yield address


@pytest.fixture(autouse=True)
def studies_on_one_dask_cluster(request, monkeypatch):
    """
    Run every study a test starts in this process on the session's one Dask cluster.

    As `--scheduler ADDRESS` would: a study without a scheduler connects to it instead of starting
    a LocalCluster of its own (a second or more per study, then per test, without it). A test
    that kills workers or checks the cluster itself is marked `own_dask_cluster`.
    """
    if request.node.get_closest_marker('own_dask_cluster'):
        return
    from cloth_bench_ros.studies import dask_executor

    start_cluster = dask_executor._cluster_client
    address = request.getfixturevalue('dask_cluster_address')

    def on_the_session_cluster(scheduler, workers, plugin):
        return start_cluster(scheduler or address(), workers, plugin)

    monkeypatch.setattr(dask_executor, '_cluster_client', on_the_session_cluster)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        '--timing-tests', choices=('with', 'apart', 'only'), default='with',
        help='tests marked timing: run with the others (default), leave them out, or only them',
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """
    Select the timing tests as --timing-tests says; run test_install.py (minutes of pip) first.

    A timing test measures wall-clock behaviour, which a second xdist process beside it disturbs:
    ./quickstart.sh test runs the rest in two processes, then these alone (`apart`, then `only`).
    """
    mode = config.getoption('--timing-tests')
    if mode != 'with':
        wanted = mode == 'only'
        timed = [item.get_closest_marker('timing') is not None for item in items]
        config.hook.pytest_deselected(items=[i for i, t in zip(items, timed) if t != wanted])
        items[:] = [i for i, t in zip(items, timed) if t == wanted]
    items.sort(key=lambda item: item.path.name != 'test_install.py')  # stable: else as collected
