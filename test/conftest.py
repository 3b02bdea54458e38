"""Fixtures shared by the tests: small real MCAP bags made on the spot."""

from __future__ import annotations

import os
import random
from pathlib import Path

import numpy as np
import pytest

from cloth_bench_ros.data import BagWriter, TrialInfo
from cloth_bench_ros.core.scene import ClothGrid

FPS = 30.0


def write_hanging_cloth_bag(path: Path, frames: int = 132, points_per_side: int = 25, seed: int = 0,
                            primitive: str = "dynamic", change_of_phase_frame: int | None = 99) -> Path:
    """A bag of a flat cloth hanging at rest (0.5 x 0.7 m, x-z plane), with 1 mm noise, at 30 Hz."""
    rng = np.random.default_rng(seed)
    grid = ClothGrid(points_per_side, points_per_side).vertices()
    trial = TrialInfo(cloth="towel", trial=0, primitive=primitive, change_of_phase_frame=change_of_phase_frame,
                      source="test fixture: flat hanging cloth")
    with BagWriter(path, trial=trial) as bag:
        for k in range(frames):
            points = grid + rng.normal(scale=0.001, size=grid.shape)
            bag.write_cloud("/cloth_bench/real/cloud", round(k * 1e9 / FPS), points)
    return path


@pytest.fixture(scope="session")
def hanging_bag(tmp_path_factory) -> Path:
    return write_hanging_cloth_bag(tmp_path_factory.mktemp("bags") / "hanging")


@pytest.fixture(scope="session", autouse=True)
def dds_on_loopback():
    """Every DDS participant of the run (here and in the node processes tests start) on loopback.

    Interface lo, no multicast, peer 127.0.0.1, on a random ROS domain so parallel runs stay apart.
    """
    from cloth_bench_ros.runtime.dds import loopback_environment

    entries = {**loopback_environment(random.randint(1, 200)), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    saved = {key: os.environ.get(key) for key in [*entries, "ROS_STATIC_PEERS"]}
    os.environ.update(entries)
    os.environ.pop("ROS_STATIC_PEERS", None)
    yield entries
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
