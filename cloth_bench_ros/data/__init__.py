"""Data layer: rosbag2 MCAP bags (read, write, inspect) and the dataset importer."""

from cloth_bench_ros.data.bag import (
    CLOUD_TOPIC,
    TARGETS_TOPIC,
    TRIAL_TOPIC,
    BagError,
    BagReader,
    BagWarning,
    BagWriter,
    CloudStats,
    TrialInfo,
    describe,
)
from cloth_bench_ros.data.messages import deserialize, serialize

__all__ = [
    "CLOUD_TOPIC",
    "TARGETS_TOPIC",
    "TRIAL_TOPIC",
    "BagError",
    "BagReader",
    "BagWarning",
    "BagWriter",
    "CloudStats",
    "TrialInfo",
    "describe",
    "deserialize",
    "serialize",
]
