"""
The one executor of the studies: Dask distributed.

By default a LocalCluster of worker processes (one single-threaded worker per core) bound to
127.0.0.1, without a dashboard; `--scheduler tcp://HOST:8786` uses an existing cluster instead
(`dask scheduler` / `dask worker` on other machines, or dask-jobqueue on a batch system). The
client keeps the study (which cells, the Optuna study, the results file); workers only simulate.

- A worker lost in the middle of a task (killed, out of memory, a segfault in an engine) loses
  no task: the scheduler runs it again on another worker; a task that kills
  `distributed.scheduler.allowed-failures` + 1 workers is run once more alone, and reported to
  `on_crash` if it kills its workers again.
- Every worker keeps the k-d trees of the real clouds it has scored (`WORKER_TREE_CACHE_POINTS`
  points at most), so a cell on a bag the worker has seen builds no tree again.
- A command starts one cluster at most (`ClusterOnDemand`): rank's identifications and cells all
  run on it, started when the first of them needs it (none when everything was kept).
- The processes of a LocalCluster are children of the client; each watches its parent through a
  pipe and exits when the client dies, even by SIGKILL (distributed's AsyncProcess does this; the
  test suite checks it), so no worker outlives its study.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path
import signal
import socket
from typing import Any, Callable, Iterator, Sequence
import warnings

from cloth_bench_ros.core import metrics
from cloth_bench_ros.studies.errors import check_scheduler_address, ExecutorError
from distributed import as_completed, Client, KilledWorker, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin
import numpy as np

WORKER_TREE_CACHE_POINTS = 20_000_000  # ~ 400 frames of 50,000 points per worker
_THREAD_VARS = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')


@contextlib.contextmanager
def quiet_shutdown() -> Iterator[None]:
    """On an interrupt, take the cluster down quietly and without a second interrupt."""
    try:
        yield
    except KeyboardInterrupt:
        signal.signal(
            signal.SIGINT, signal.SIG_IGN
        )  # a second Ctrl-C must not cut the clean-up short
        logging.getLogger('distributed').setLevel(logging.CRITICAL)
        logging.getLogger('asyncio').setLevel(logging.CRITICAL)
        warnings.filterwarnings('ignore', message='coroutine .* was never awaited')
        raise


def default_workers() -> int:
    """One worker process per core."""
    return max(1, os.cpu_count() or 1)


class _WorkerSetup(WorkerPlugin):
    """Worker plugin: quiet output (to the study's log), one numpy thread, the tree cache."""

    name = 'cloth-bench-setup'

    def __init__(self, log_path: str | None, local: bool) -> None:
        self.log_path = log_path
        self.local = local

    def setup(self, worker: Any) -> None:
        for var in _THREAD_VARS:
            os.environ.setdefault(var, '1')  # the engines are single-threaded: one core per worker
        metrics.keep_trees(WORKER_TREE_CACHE_POINTS)
        cloud = np.eye(3)
        metrics.RealCloud(cloud).chamfer_hausdorff(cloud)  # load the compiled kernels now
        if self.local and self.log_path:
            # What the engines' C code prints goes to the log, not to the terminal of the progress
            # bar.
            try:
                fd = os.open(self.log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
                os.dup2(fd, 1)
                os.dup2(fd, 2)
                os.close(fd)
            except OSError:
                pass
        warnings.simplefilter('ignore')


@contextlib.contextmanager
def open_client(
    scheduler: str | None = None, workers: int | None = None, log_path: Path | None = None
) -> Iterator[Any]:
    """Return a Dask client of a new LocalCluster on 127.0.0.1, or of `scheduler`."""
    for var in _THREAD_VARS:
        os.environ.setdefault(var, '1')
    logging.getLogger('distributed').setLevel(logging.ERROR)
    plugin = _WorkerSetup(str(log_path) if log_path else None, scheduler is None)
    with (
        _cluster_client(scheduler, workers, plugin) as client,
        quiet_shutdown(),
    ):  # quiet before closing
        yield client


class ClusterOnDemand:
    """
    The one cluster of a command, started (by `open_client`) when `client()` is first called.

    `with ClusterOnDemand(scheduler, workers, log) as cluster:` then `cluster.client()` wherever a
    step of the command needs workers: every step runs on the same client, and a command whose
    results were all kept starts none. Leaving the block closes it (an interrupt quietly).
    """

    def __init__(
        self, scheduler: str | None = None, workers: int | None = None,
        log_path: Path | None = None,
    ) -> None:
        self._open = (scheduler, workers, log_path)
        self._stack = contextlib.ExitStack()
        self._client: Any = None

    def client(self) -> Any:
        """Return the command's client, starting its cluster (or connecting) the first time."""
        if self._client is None:
            self._client = self._stack.enter_context(open_client(*self._open))
        return self._client

    def __enter__(self) -> 'ClusterOnDemand':
        return self

    def __exit__(self, *exc: Any) -> bool | None:
        return self._stack.__exit__(*exc)


@contextlib.contextmanager
def _cluster_client(
    scheduler: str | None, workers: int | None, plugin: _WorkerSetup
) -> Iterator[Any]:
    if scheduler is not None:
        address = check_scheduler_address(scheduler)
        try:
            client = Client(address, timeout='20s')
        except (OSError, TimeoutError) as exc:
            raise ExecutorError(f'--scheduler {address}: cannot connect ({exc})') from None
        try:
            _register(client, plugin)
            yield client
        finally:
            client.close()
        return
    cluster = LocalCluster(
        n_workers=workers or default_workers(),
        threads_per_worker=1,
        processes=True,
        host='127.0.0.1',
        dashboard_address=None,
        memory_limit=0,
        silence_logs=logging.ERROR,
        # No dashboard; the scheduler's HTTP routes (health) on a free loopback port.
        scheduler_kwargs={'dashboard': False, 'dashboard_address': '127.0.0.1:0'},
    )
    try:
        client = Client(cluster)
        try:
            _register(client, plugin)
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def _register(client: Any, plugin: _WorkerSetup) -> None:
    if hasattr(client, 'register_plugin'):
        client.register_plugin(plugin, name=plugin.name)
    else:  # distributed before 2023.9
        client.register_worker_plugin(plugin, name=plugin.name)


def worker_slots(client: Any) -> int:
    """Threads of the cluster's workers now (at least 1)."""
    return max(1, sum(client.nthreads().values()))


def run_tasks(
    client: Any,
    func: Callable,
    items: Sequence,
    on_result: Callable[[Any, Any], None],
    on_crash: Callable[[Any, str], None],
    args: tuple = (),
    in_flight: int | None = None,
) -> None:
    """
    Run func(item, *args) for every item on the cluster, at most `in_flight` at a time.

    The default is twice the worker threads; on_result(item, result) runs in the client as each
    finishes.

    A worker that dies counts against every task it held, so a task beside the one that kills its
    workers can be declared killed too. Killed tasks run again at the end, one at a time: an
    innocent one then finishes, and only the one that kills its workers alone goes to on_crash.
    An exception a task raises (a bug: the tasks return their failures as results) is raised here.
    """
    limit = in_flight or 2 * worker_slots(client)
    pending = list(items)[::-1]
    futures = as_completed()
    owner: dict[str, Any] = {}
    suspects: list = []

    def submit(item: Any) -> None:
        future = client.submit(func, item, *args, pure=False)
        owner[future.key] = item
        futures.add(future)

    for _ in range(min(limit, len(pending))):
        submit(pending.pop())
    for future in futures:
        item = owner.pop(future.key)
        try:
            result = future.result()  # a task's exception (a bug) is raised here, as it is
        except KilledWorker:
            suspects.append(item)
        else:
            on_result(item, result)
        finally:
            future.release()
        if pending:
            submit(pending.pop())
    for item in suspects:
        future = client.submit(func, item, *args, pure=False)
        try:
            result = future.result()
        except KilledWorker:
            on_crash(item, 'the worker process died while running this case (on every worker that'
                     ' tried it)')
        else:
            on_result(item, result)
        finally:
            future.release()


def host_label() -> str:
    """Return this machine's name and core count, for provenance."""
    return f'{socket.gethostname()} ({os.cpu_count()} cores)'
