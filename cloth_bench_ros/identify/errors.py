"""What identify reports in one line: an output fitted to another problem."""

from cloth_bench_ros.errors import InputError


class ProblemChanged(InputError):
    """An output's journal was fitted to another problem; `changed` names what changed."""

    def __init__(self, message: str, changed: str) -> None:
        super().__init__(message)
        self.changed = changed
