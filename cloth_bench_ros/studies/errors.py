"""
Outcomes of a study that the command line reports in one line (light: no Dask or DDS import).

With the check of a --scheduler address, which the parser runs without loading Dask.
"""

from cloth_bench_ros.errors import ClothBenchError


class StudyInterrupted(Exception):
    """A study stopped by Ctrl-C: str() is one line saying what was kept and how to resume."""


class ProcessRunError(ClothBenchError, RuntimeError):
    """A node process failed or the run did not end in time; str() names the node and its line."""


class RunTimeout(ProcessRunError):
    """A run that did not end in time: the machine's load or a stuck graph, not a result."""


class ExecutorError(ClothBenchError, ValueError):
    """A scheduler that cannot be reached or used; str() is one line."""


def check_scheduler_address(address: str) -> str:
    """`address` if it looks like tcp://HOST:PORT (or tls://), else ExecutorError."""
    scheme, sep, rest = address.partition('://')
    host, colon, port = rest.rpartition(':')
    if not sep or scheme not in ('tcp', 'tls') or not colon or not host or not port.isdigit():
        raise ExecutorError(
            f'--scheduler {address!r} is not tcp://HOST:PORT (e.g. tcp://127.0.0.1:8786)'
        )
    return address
