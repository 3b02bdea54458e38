"""
Time as rclpy keeps it: Time, clocks (ROS, system, steady) and timers on a clock.

Follows rclpy/time_source.py (a ROS clock under sim time reads the last /clock message, 0 before
the first one), rclpy/node.py create_timer (timers on the node's clock unless one is given) and
rcl/src/rcl/timer.c rcl_timer_call (a call moves the next one by whole periods).
"""

from __future__ import annotations

import enum
import time
from typing import Any, Callable

from cloth_bench_ros.runtime import messages


class Time:
    """A point in ROS time, in integer nanoseconds."""

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        self.nanoseconds = int(seconds * 1_000_000_000) + int(nanoseconds)

    @classmethod
    def from_msg(cls, msg: Any) -> 'Time':
        return cls(nanoseconds=int(msg.sec) * 1_000_000_000 + int(msg.nanosec))

    def to_msg(self) -> Any:
        sec, nanosec = divmod(self.nanoseconds, 1_000_000_000)
        return messages.Time(sec=sec, nanosec=nanosec)

    def __repr__(self) -> str:
        return f'Time(nanoseconds={self.nanoseconds})'


class ClockType(enum.IntEnum):
    """rclpy.clock_type.ClockType."""

    UNINITIALIZED = 0
    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3


class Clock:
    """
    rclpy's Clock: ROS time, system time or steady time.

    ROS time is system time, or the last /clock once sim time is active.

    As rclpy's time source, a ROS clock with sim time active reads 0 until the first /clock message
    (rclpy/time_source.py: "Zero time is a special value that means time is uninitialized").
    """

    def __init__(self, *, clock_type: ClockType = ClockType.SYSTEM_TIME) -> None:
        self.clock_type = clock_type
        self.ros_time_is_active = False
        self.sim_time_ns = 0

    def now(self) -> Time:
        if self.clock_type == ClockType.STEADY_TIME:
            return Time(nanoseconds=time.monotonic_ns())
        if self.clock_type == ClockType.ROS_TIME and self.ros_time_is_active:
            return Time(nanoseconds=self.sim_time_ns)
        return Time(nanoseconds=time.time_ns())


class Timer:
    """
    An rcl timer on a clock (the node's by default: sim time under use_sim_time).

    The first call is due one period after creation; a call moves the next one by whole periods,
    skipping the ones missed (rcl/src/rcl/timer.c rcl_timer_call). On a sim clock it is due only
    when /clock has reached it: waiting does not make it due.
    """

    def __init__(self, period: float, callback: Callable, clock: Clock) -> None:
        self.period_ns = max(1, int(period * 1e9))
        self.callback = callback
        self.clock = clock
        self.next_ns = clock.now().nanoseconds + self.period_ns
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True

    def is_canceled(self) -> bool:
        return self.cancelled

    def reset(self) -> None:
        self.cancelled = False
        self.next_ns = self.clock.now().nanoseconds + self.period_ns

    def is_ready(self) -> bool:
        return not self.cancelled and self.clock.now().nanoseconds >= self.next_ns

    def time_until_next_call(self) -> int | None:
        """Ns until the next call on this timer's clock; None once cancelled."""
        return None if self.cancelled else self.next_ns - self.clock.now().nanoseconds

    @property
    def follows_wall_time(self) -> bool:
        """Return False for a timer on an active sim clock: only /clock makes it due."""
        return not (self.clock.clock_type == ClockType.ROS_TIME and self.clock.ros_time_is_active)

    def call(self) -> None:
        now = self.clock.now().nanoseconds
        self.next_ns += self.period_ns
        if self.next_ns <= now:
            self.next_ns += (1 + (now - self.next_ns) // self.period_ns) * self.period_ns
        self.callback()
