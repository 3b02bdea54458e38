"""rclpy.qos for the embedded runtime: the policy enums and QoSProfile (a leaf module)."""

from __future__ import annotations

from dataclasses import dataclass
import enum


class ReliabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.IntEnum):
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass
class QoSProfile:
    depth: int = 10
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE
    history: HistoryPolicy = HistoryPolicy.KEEP_LAST


def as_profile(qos: QoSProfile | int) -> QoSProfile:
    """Rclpy's `qos_profile` argument: a profile, or a depth meaning keep-last of that depth."""
    return QoSProfile(depth=qos) if isinstance(qos, int) else qos


def time_source_qos() -> QoSProfile:
    """Return the /clock subscription QoS of rclpy's TimeSource: depth 1, best effort."""
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
