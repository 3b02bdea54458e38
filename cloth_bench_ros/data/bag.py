"""Compatibility module: the bag layer now lives in errors, trial, bag_reader, bag_writer, bag_info.

New code imports from `cloth_bench_ros.data`; this keeps `cloth_bench_ros.data.bag` imports working.
"""

from cloth_bench_ros.data.bag_info import describe
from cloth_bench_ros.data.bag_reader import IRREGULAR_TOLERANCE, BagReader, CloudStats
from cloth_bench_ros.data.bag_writer import METADATA_VERSION, ROS_DISTRO, BagWriter
from cloth_bench_ros.data.errors import BagError, BagWarning
from cloth_bench_ros.data.trial import (
    CLOUD_TOPIC, CUSTOM_DATA_PREFIX, MCAP_TRIAL_RECORD, TARGETS_TOPIC, TRIAL_STATUS_NAME, TRIAL_TOPIC,
    TrialInfo, trial_from_message, trial_message,
)

__all__ = [
    "CLOUD_TOPIC", "CUSTOM_DATA_PREFIX", "IRREGULAR_TOLERANCE", "MCAP_TRIAL_RECORD", "METADATA_VERSION",
    "ROS_DISTRO", "TARGETS_TOPIC", "TRIAL_STATUS_NAME", "TRIAL_TOPIC", "BagError", "BagReader", "BagWarning",
    "BagWriter", "CloudStats", "TrialInfo", "describe", "trial_from_message", "trial_message",
]
