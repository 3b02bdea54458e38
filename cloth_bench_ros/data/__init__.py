"""Data layer: rosbag2 MCAP bags (read, write, inspect) and the dataset importer."""

from cloth_bench_ros.data.bag_info import describe
from cloth_bench_ros.data.bag_reader import IRREGULAR_TOLERANCE, BagReader, CloudStats
from cloth_bench_ros.data.bag_writer import METADATA_VERSION, ROS_DISTRO, BagWriter
from cloth_bench_ros.data.errors import BagError, BagWarning
from cloth_bench_ros.data.messages import deserialize, serialize
from cloth_bench_ros.data.trial import (
    CLOUD_TOPIC, CUSTOM_DATA_PREFIX, MCAP_TRIAL_RECORD, TARGETS_TOPIC, TRIAL_STATUS_NAME, TRIAL_TOPIC,
    TrialInfo, trial_from_message, trial_message,
)

__all__ = [
    "CLOUD_TOPIC",
    "CUSTOM_DATA_PREFIX",
    "IRREGULAR_TOLERANCE",
    "MCAP_TRIAL_RECORD",
    "METADATA_VERSION",
    "ROS_DISTRO",
    "TARGETS_TOPIC",
    "TRIAL_STATUS_NAME",
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
    "trial_from_message",
    "trial_message",
]
