"""Data layer: rosbag2 MCAP bags (read, write, inspect) and the dataset importer."""

from cloth_bench_ros.data.bag_info import describe
from cloth_bench_ros.data.bag_reader import BagReader, CloudStats
from cloth_bench_ros.data.bag_writer import BagWriter
from cloth_bench_ros.data.errors import BagError, BagWarning
from cloth_bench_ros.data.messages import deserialize, serialize
from cloth_bench_ros.data.trial import CLOUD_TOPIC, TARGETS_TOPIC, TRIAL_TOPIC, TrialInfo

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
