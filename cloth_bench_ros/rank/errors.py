"""What rank reports in one line: a recording it cannot read, a ranking it cannot give."""

from cloth_bench_ros.errors import ClothBenchError


class RankInputError(ClothBenchError, ValueError):
    """A recording given to rank cannot be read; str() names it and says why."""


class RankError(ClothBenchError, ValueError):
    """Rank cannot give an answer (no group with two usable trials); str() says why."""
