"""
What identify and rank record of a user's recording: the task, the cloth mesh, grippers and table.

Each of a study's trials runs along a task (a shipped one, a `--task` file, or a recording's own
motion, carried by its trial bag) on a grid or a `--cloth-mesh`; the files' content hashes go
into identification.json, rank.json, the journals' problems and the cells' keys, so that another
task file or mesh is computed again, never reused.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Sequence

from cloth_bench_ros.core.task_data import load_task
from cloth_bench_ros.errors import user_path


def file_sha256(path: str) -> str:
    """Return the sha256 of a file's bytes ('' for no file)."""
    if not path:
        return ''
    with user_path(Path(path)):
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def task_record(primitive: str, task: str) -> dict[str, str]:
    """Return a task's file and content hash (`task`: a file, '' for the shipped `primitive`)."""
    loaded = load_task(primitive, task or None)
    return {'file': loaded.path, 'sha256': loaded.sha256}


def mesh_record(mesh: str) -> dict[str, str] | None:
    """Return a `--cloth-mesh` file and its content hash (None: the grid)."""
    return {'file': mesh, 'sha256': file_sha256(mesh)} if mesh else None


def inputs_record(
    primitive: str, tasks: Sequence[str], mesh: str, gripper_frames: str = '',
    table_z: float | None = None,
) -> dict[str, Any]:
    """Return what a study's JSON records of its inputs: tasks, mesh, grippers, table height."""
    return {
        'tasks': [task_record(primitive, t) for t in tasks],
        'cloth_mesh': mesh_record(mesh),
        'gripper_frames': gripper_frames or None,
        'table_z': table_z,
    }


def inputs_key(primitive: str, task: str, mesh: str) -> str:
    """Return the part of a cache key that names the task's and the mesh's content."""
    return f'task:{task_record(primitive, task)["sha256"][:16]}|mesh:{file_sha256(mesh)[:16]}'
