"""Errors of the data layer: one class per failure domain, each with only a docstring."""

from cloth_bench_ros.errors import ClothBenchError


class BagError(ClothBenchError):
    """A bag that cannot be read or written; str() is one line naming the bag and the problem."""


class BagWarning(UserWarning):
    """A bag that reads, but not completely (truncated file, missing metadata.yaml)."""
