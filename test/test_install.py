"""
`pip install .` as the README offers it, with each extra, in a fresh venv.

The main job runs and a camera-like recording scores; an engine whose extra is missing is one
line naming it, exit 2. Slow (minutes per install: pip from its cache or the index): `-m slow`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
import shutil
import subprocess
import sys

from camera_recording import CAMERA_TOPIC, EPOCH_START_NS, make_camera_recording
import pytest

REPO = Path(__file__).resolve().parent.parent
INSTALL_TIMEOUT_S = 1500
RUN_TIMEOUT_S = 900
FAST = ['--grid', '6x8']


def _source_copy(target: Path) -> Path:
    """Copy the repository's files (as a fresh clone has them) to `target`."""
    files = subprocess.run(
        ['git', 'ls-files', '-co', '--exclude-standard'],
        cwd=REPO, capture_output=True, text=True, check=True,
    ).stdout.split()
    for rel in files:
        if (REPO / rel).is_file():
            (target / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / rel, target / rel)
    return target


def _fresh_venv(tmp_path: Path) -> tuple[Path, Path]:
    """Return the bin folder of a new venv and a copy of the repository to install from."""
    source = _source_copy(tmp_path / 'src')
    venv = tmp_path / 'venv'
    subprocess.run([sys.executable, '-m', 'venv', str(venv)], check=True, timeout=300)
    return venv / 'bin', source


def _pip_install(bin_dir: Path, spec: str) -> None:
    """`pip install spec` into the venv of `bin_dir`."""
    # --no-compile: Python writes the bytecode of what a run imports as it imports it; compiling
    # every installed module up front (open3d, scipy, matplotlib...) took a third of the install
    done = subprocess.run(
        [str(bin_dir / 'python'), '-m', 'pip', 'install', '-q', '--no-compile', spec],
        capture_output=True, text=True, timeout=INSTALL_TIMEOUT_S,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]


def _cloth_bench(bin_dir: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ('PYTHONPATH', 'VIRTUAL_ENV')}
    env['PATH'] = f'{bin_dir}:{env.get("PATH", "")}'
    return subprocess.run(
        [str(bin_dir / 'cloth-bench'), *args],
        cwd=cwd, env=env, capture_output=True, text=True, timeout=RUN_TIMEOUT_S,
    )


def scored(run: subprocess.CompletedProcess, out: Path, *engines: str) -> dict:
    """Return the summary of a `cloth-bench run` that exited 0 and scored each of `engines`."""
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    summary = json.loads((out / 'summary.json').read_text())
    for engine in engines:
        scores = summary['engines'][engine]
        assert scores['frames_scored'] > 0 and 0 < scores['CD_d'] < 0.2, (engine, scores)
    return summary


def camera_run(folder: Path) -> list[str]:
    """Write a camera-like copy of the bundled fling in `folder`; return the run's arguments."""
    camera = folder / 'camera'
    if not camera.exists():
        make_camera_recording(REPO / 'bags' / 'towel_dynamic', camera, seed=3, noise=0.002)
    return ['run', '--bag', str(camera), '--topic', CAMERA_TOPIC,
            '--start-time', f'{EPOCH_START_NS / 1e9:.9f}', *FAST]


def _main_job_and_camera(bin_dir: Path, work: Path, *engines: str) -> None:
    """Run the README's main job on the bundled bag, then a camera-like recording: both score."""
    chosen = [arg for engine in engines for arg in ('--engine', engine)]
    out = work / f'bundled_{"_".join(engines)}'
    run = _cloth_bench(bin_dir, work, 'run', *chosen, *FAST, '--output', str(out))
    scored(run, out, *engines)
    # organized clouds in the camera's frame, table and background in view, no project
    # metadata: cleaned by default
    out = work / f'camera_{"_".join(engines)}'
    run = _cloth_bench(bin_dir, work, *camera_run(work), *chosen, '--output', str(out))
    summary = scored(run, out, *engines)
    assert summary['real']['cleaning']['table_plane'] > 0  # the cleaning ran, table and all


@pytest.mark.slow
def test_pip_install_and_each_extra_run_the_main_job_and_score_a_camera_recording(tmp_path):
    # One venv: the plain install first, so it is checked without any extra's packages, then
    # both extras in one step (one more resolve and build, not two) and their two engines run.
    bin_dir, source = _fresh_venv(tmp_path)
    work = tmp_path / 'work'
    work.mkdir()
    _pip_install(bin_dir, str(source))
    _main_job_and_camera(bin_dir, work, 'mujoco')
    run = _cloth_bench(bin_dir, work, 'run', '--engine', 'newton', *FAST,
                       '--output', str(work / 'no_newton'))  # its extra is missing: one line
    assert run.returncode == 2, run.stderr
    assert run.stderr.count('\n') == 1 and 'Traceback' not in run.stderr
    assert "pip install 'cloth_bench_ros[newton]'" in run.stderr
    _pip_install(bin_dir, f'{source}[test,newton]')
    _main_job_and_camera(bin_dir, work, 'bullet', 'newton')
