"""Outcomes of a study that the command line reports in one line (light: no Dask or DDS import)."""

from cloth_bench_ros.errors import ClothBenchError


class StudyInterrupted(Exception):
    """A study stopped by Ctrl-C: str() is one line saying what was kept and how to resume."""


class ProcessRunError(ClothBenchError, RuntimeError):
    """A node process failed or the run did not end in time; str() names the node and its line."""


class RunTimeout(ProcessRunError):
    """A run that did not end in time: the machine's load or a stuck graph, not a result."""
