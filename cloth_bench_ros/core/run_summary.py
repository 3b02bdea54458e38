"""A run's summary: what the evaluator publishes on `metrics` and writes to summary.json."""

from __future__ import annotations

from typing import Any

from cloth_bench_ros.core.evaluation import frame_accounting, OnlineEvaluator


def change_of_phase_used(used: int | None, replay: dict[str, Any]) -> dict[str, Any]:
    """Return the scored window's end as used: its frame and source (option, metadata, ...)."""
    told = dict(replay.get('change_of_phase') or {})
    if told.get('frame') != used:  # the evaluator's own parameter overrides the recorder's choice
        told = {
            'frame': used,
            'source': 'option' if used is not None else 'none',
            'reason': (
                'evaluator parameter change_of_phase_frame' if used is not None else 'not given'
            ),
        }
    return told


def run_summary(
    core: OnlineEvaluator,
    replay: dict[str, Any],
    run: dict[str, Any],
    period_s: float,
    wall_s: float | None,
    final_stamp_ns: int,
) -> dict[str, Any]:
    """
    Return the summary of a finished evaluation: run, real frames and their accounting, engines.

    `replay` is the recorder's frame accounting; `run` the run's settings with its trial.
    """
    core.finish()
    engines = core.summary(period_s, wall_s, final_stamp_ns / 1e9)
    real: dict[str, Any] = dict(core.real_summary())
    # NaN points and stamp intervals are counted by the recorder on every frame of the bag.
    real['nan_points_dropped'] += int(replay.get('nan_points_dropped', 0))
    real['irregular_intervals'] = int(
        replay.get('irregular_intervals', real['irregular_intervals'])
    )
    accounting = frame_accounting(replay, real)
    return {
        'run': {**run, 'wall_time': wall_s},
        'real': {
            **real,
            'accounting': accounting,
            'alignment': replay.get('start'),
            'trials': replay.get('trials'),
            'frames_from': replay.get('frames'),
            'cleaning': replay.get('cleaning'),
            'topic': replay.get('topic'),
            'targets_grasp_m': replay.get('targets_grasp_m'),
            'change_of_phase': change_of_phase_used(core.change_of_phase_frame, replay),
        },
        'engines': engines,
    }


def inputs_line(summary: dict) -> str:
    """
    Return which task file, recorded motion and cloth mesh a run used, in one line.

    '' for the shipped task on the grid (summary.json's `task_file`, `motion`, `cloth_mesh`).
    """
    run = summary['run']
    parts = []
    task_file = str(run.get('task_file') or '')
    if task_file and not task_file.startswith('config/tasks/'):
        parts.append(f'task {task_file} (sha256 {str(run.get("task_sha256", ""))[:12]})')
    motion = run.get('motion')
    if motion:
        table = motion.get('table_z')
        parts.append(
            f'motion recorded ({motion.get("source")}, in {motion.get("frame")}; table '
            + (f'{table:.3f} m' if isinstance(table, (int, float)) else 'none') + ')'
        )
    mesh = run.get('cloth_mesh')
    if mesh:
        parts.append(
            f'cloth mesh {mesh.get("file")} ({mesh.get("vertices")} vertices, '
            f'{mesh.get("triangles")} triangles, sha256 {str(mesh.get("sha256", ""))[:12]})'
        )
    return 'run of: ' + '; '.join(parts) if parts else ''
