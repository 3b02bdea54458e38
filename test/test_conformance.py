"""
Differential conformance: the strictness cases of conformance_cases.py under every runtime.

The same script runs on real rclpy (Jazzy over Fast DDS, in a loopback-only network namespace)
and on the embedded runtime with each of its transports; the test compares the outcomes case by
case, so that wherever the embedded runtime behaves differently from real rcl/rclpy, it fails.
Exceptions are compared by class (their texts differ and are not compared).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from cloth_bench_ros.runtime.dds import loopback_environment
from conformance_cases import ISOLATED
from dds_domains import random_domain
import pytest
from real_ros import in_namespace, require_real_ros, ROOT, ros_env

CASES = str(ROOT / 'test' / 'conformance_cases.py')

# Where a difference from real rclpy is intended: case -> why. None at present; a case added here
# is still run, and its outcome under each runtime printed, but not compared.
INTENDED_DIFFERENCES: dict[str, str] = {}


def _outcomes(run_cases) -> dict:
    """Return every case's outcome: one process for most, one each for the isolated ones."""
    outcomes = run_cases([])
    for name in ISOLATED:
        outcomes.update(run_cases([name]))
    return outcomes


def _embedded(transport: str) -> dict:
    return _outcomes(lambda names: _embedded_cases(transport, names))


def _real() -> dict:
    return _outcomes(_real_cases)


def _embedded_cases(transport: str, names: list[str]) -> dict:
    env = {
        **os.environ,
        'CLOTH_BENCH_EMBEDDED': '1',
        'CLOTH_BENCH_TRANSPORT': transport,
        'PYTHONPATH': str(ROOT),
    }
    if transport == 'dds':
        env.update(loopback_environment(random_domain()))
    out = subprocess.run(
        [sys.executable, CASES, *names], capture_output=True, text=True, env=env, timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)


def _real_cases(names: list[str]) -> dict:
    out = subprocess.run(
        in_namespace(CASES, *names), capture_output=True, text=True, env=ros_env(), timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)


def _differences(expected: dict, actual: dict) -> list[str]:
    return [
        f'{case}: expected {expected[case]!r}, got {actual.get(case)!r}'
        for case in expected
        if not case.startswith('_')
        and case not in INTENDED_DIFFERENCES
        and expected[case] != actual.get(case)
    ]


@pytest.fixture(scope='module')
def intra() -> dict:
    return _embedded('intra')


@pytest.mark.slow
def test_the_embedded_transports_agree_case_by_case(intra):
    dds = _embedded('dds')
    assert intra['_runtime'] == dds['_runtime'] == 'embedded'
    assert len(intra) > 60
    assert _differences(intra, dds) == []


@pytest.mark.slow
@pytest.mark.real_ros
def test_the_embedded_runtime_behaves_as_real_rclpy_case_by_case(intra):
    require_real_ros()
    real = _real()
    assert real['_runtime'] == 'rclpy'
    assert set(real) == set(intra)
    for case, why in INTENDED_DIFFERENCES.items():
        print(f'{case}: real {real[case]!r}, embedded {intra[case]!r} ({why})')
    assert _differences(real, intra) == []
