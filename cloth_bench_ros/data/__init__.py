"""Data layer: rosbag2 MCAP bags (read, write, inspect) and the dataset importer."""

from cloth_bench_ros.data.bag_info import describe
from cloth_bench_ros.data.bag_reader import BagReader, CloudStats, IRREGULAR_TOLERANCE
from cloth_bench_ros.data.bag_writer import BagWriter, METADATA_VERSION, ROS_DISTRO
from cloth_bench_ros.data.errors import BagError, BagWarning
from cloth_bench_ros.data.messages import deserialize, serialize
from cloth_bench_ros.data.trial import (
    CLOUD_TOPIC,
    CUSTOM_DATA_PREFIX,
    MCAP_TRIAL_RECORD,
    TARGETS_TOPIC,
    trial_from_message,
    trial_message,
    TRIAL_STATUS_NAME,
    TRIAL_TOPIC,
    TrialInfo,
)

__all__ = [
    'CLOUD_TOPIC',
    'CUSTOM_DATA_PREFIX',
    'IRREGULAR_TOLERANCE',
    'MCAP_TRIAL_RECORD',
    'METADATA_VERSION',
    'ROS_DISTRO',
    'TARGETS_TOPIC',
    'TRIAL_STATUS_NAME',
    'TRIAL_TOPIC',
    'BagError',
    'BagReader',
    'BagWarning',
    'BagWriter',
    'CloudStats',
    'TrialInfo',
    'describe',
    'deserialize',
    'serialize',
    'trial_from_message',
    'trial_message',
]
