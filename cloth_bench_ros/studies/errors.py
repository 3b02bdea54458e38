"""Outcomes of a study that the command line reports in one line (light: no Dask import)."""


class StudyInterrupted(Exception):
    """A study stopped by Ctrl-C: str() is one line saying what was kept and how to resume."""
