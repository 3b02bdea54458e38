"""
The real-ROS 2 tier's harness: the project on real rclpy (Jazzy wheels from PyPI) in its own venv.

Every command runs inside a network namespace of its own with only loopback up (`unshare -n`), so
Fast DDS, which multicasts on every interface by default, cannot leave the machine. The venv is
made by `./quickstart.sh test` (`.venv-ros`, or CLOTH_BENCH_ROS_VENV); without it, or where
namespaces cannot be made, the tier is skipped with the reason, except under CI, where it fails.
"""

from __future__ import annotations

import os
from pathlib import Path
import subprocess

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROS_VENV = Path(os.environ.get('CLOTH_BENCH_ROS_VENV', ROOT / '.venv-ros'))
ROS_PYTHON = ROS_VENV / 'bin' / 'python'
NAMESPACE_PREFIX = [
    'unshare',
    '-n',
    'sh',
    '-c',
    'ip link set lo up && ip link set lo multicast on && exec "$@"',
    'sh',
]


def _unavailable() -> str | None:
    if not ROS_PYTHON.exists():
        return f'no real-ROS 2 venv at {ROS_VENV} (./quickstart.sh test makes it)'
    probe = subprocess.run([*NAMESPACE_PREFIX, 'true'], capture_output=True, text=True)
    if probe.returncode != 0:
        return (
            'cannot make a loopback-only network namespace (unshare -n):'
            f' {probe.stderr.strip()[:200]}'
        )
    return None


def require_real_ros() -> None:
    """Skip (print the reason) where the tier cannot run; under CI it must run: fail instead."""
    reason = _unavailable()
    if reason is None:
        return
    if os.environ.get('CI'):
        pytest.fail(f'real-ROS 2 tier cannot run under CI: {reason}')
    pytest.skip(reason)


def ros_env(**extra: str) -> dict[str, str]:
    """Return the environment of a real-rclpy process: this checkout first, no embedded switch."""
    dropped = (
        'CLOTH_BENCH_EMBEDDED',
        'CLOTH_BENCH_TRANSPORT',
        'CYCLONEDDS_URI',
        'ROS_STATIC_PEERS',
    )
    env = {k: v for k, v in os.environ.items() if k not in dropped}
    env['PYTHONPATH'] = str(ROOT)
    env.update(extra)
    return env


def in_namespace(*argv: str) -> list[str]:
    """Argv run with the real-ROS 2 venv's Python inside a loopback-only network namespace."""
    return [*NAMESPACE_PREFIX, str(ROS_PYTHON), *argv]


def ros_script(script: str) -> list[str]:
    """Return a shell script running one graph's processes in a loopback-only namespace."""
    return [
        'unshare',
        '-n',
        'sh',
        '-c',
        f'ip link set lo up && ip link set lo multicast on && {script}',
    ]
