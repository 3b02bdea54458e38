"""
Issue 12: untrusted values refused in one line naming them, no silent wrong numbers, nothing lost.

Each case asserts the exit status, a single stderr line naming the input, no traceback and, where
results existed beforehand, that they are intact afterwards. CLI cases run `cli.main` in-process
(argparse errors included); a few go through a real subprocess in test_cli.py and the fuzz test.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
import resource
import shutil
import signal
import subprocess
import sys

from cloth_bench_ros import cli, validation
from cloth_bench_ros.data import BagReader, synth, virtual_camera
from cloth_bench_ros.nodes import evaluator, recorder, simulator, trajectory_publisher
import numpy as np
import pytest
from test_importer import write_pcd, write_ply

REPO = Path(__file__).resolve().parents[1]
BUNDLED = REPO / 'bags' / 'towel_dynamic'


def run_main(capsys, main, argv) -> tuple[int, str, str]:
    """Return (status, stdout, stderr) of an in-process `main(argv)`, argparse's exit included."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(code: int, err: str, *words: str, status: int = 2) -> str:
    assert code == status, err
    assert 'Traceback' not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


def tree_digest(path: Path) -> dict[str, str]:
    return {
        str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob('*'))
        if p.is_file()
    }


# ------------------------------------------------------------------ the validation layer itself


@pytest.mark.parametrize(
    'check,value,words',
    [
        (
            lambda v: validation.integer(v, 'parameter substeps', 1),
            2.7,
            ['substeps', '2.7', 'integer'],
        ),
        (lambda v: validation.integer(v, 'parameter substeps', 1), True, ['substeps', 'integer']),
        (lambda v: validation.number(v, 'parameter mass', 0.0), True, ['mass', 'number']),
        (lambda v: validation.number(v, 'parameter mass', 0.0), '0.5', ['mass', 'number']),
        (lambda v: validation.rate_hz(v, '--rate'), float('inf'), ['--rate', 'finite']),
        (lambda v: validation.rate_hz(v, '--rate'), 1e9, ['--rate', 'outside']),
        (lambda v: validation.seed(v), -3, ['seed', '-3']),
        (
            lambda v: validation.frame_index(v, 'change_of_phase_frame', unset=-1),
            -5,
            ['change_of_phase_frame', '-5'],
        ),
        (lambda v: validation.parse_grid(v), '3000x3000', ['grid', '3000']),
        (lambda v: validation.parse_grid(v), '150x150', ['grid', '22500 vertices']),
        (
            lambda v: validation.unique(v, '--engine'),
            ['mujoco', 'mujoco'],
            ['--engine', 'mujoco', 'twice'],
        ),
        (
            lambda v: validation.parameter_mapping(v, 'parameter engine_params'),
            '{mass: ',
            ['engine_params', 'YAML'],
        ),
        (
            lambda v: validation.parameter_mapping(v, 'parameter engine_params'),
            '[1, 2]',
            ['engine_params', 'mapping'],
        ),
        (
            lambda v: validation.parameter_mapping(v, 'parameter engine_params'),
            '{a: &x [1], b: *x}',
            ['engine_params', 'a is list'],
        ),
        (
            lambda v: validation.parse_overrides(v),
            ['mujoco.mass=1', 'mujoco.mass=2'],
            ['mujoco.mass', 'twice'],
        ),
    ],
)
def test_validation_refuses_in_one_line_naming_the_input(check, value, words):
    with pytest.raises(validation.InputError) as exc:
        check(value)
    message = str(exc.value)
    assert '\n' not in message
    for word in words:
        assert word in message, message


def test_validation_accepts_what_is_right():
    assert validation.integer(3.0, 'n') == 3 and validation.integer(np.int64(4), 'n') == 4
    assert validation.rate_hz(1000, '--rate') == 1000.0
    assert (
        validation.frame_index(-1, 'cut', unset=-1) is None
        and validation.frame_index(0, 'cut') == 0
    )
    assert validation.parse_grid(' 6X8 ') == (6, 8)
    assert validation.parse_overrides(['mujoco.substeps=3', 'mujoco.self_collision=on']) == {
        'mujoco': {'substeps': 3, 'self_collision': True}
    }
    assert validation.parameter_mapping('{mass: 0.4, model: edges}', 'p') == {
        'mass': 0.4,
        'model': 'edges',
    }


# --------------------------------------------------------------------------- CLI: wrong numbers


@pytest.mark.parametrize(
    'argv,words',
    [
        (['run', '--engine', 'mujoco', '--engine', 'mujoco'], ['--engine', 'mujoco', 'twice']),
        (['run', '--set', 'mujoco.mass=true'], ['--set mujoco', 'mass', 'True']),
        (['run', '--set', 'mujoco.substeps=2.7'], ['--set mujoco', 'substeps', '2.7', 'integer']),
        (['run', '--set', 'mujoco.mass=nan'], ['--set mujoco', 'mass', 'nan']),
        (['run', '--presets', 'no/such/presets'], ['presets', 'no/such/presets']),
        (['run', '--rate', '1e9'], ['--rate', '1000000000']),
        (['run', '--rate', 'inf'], ['--rate', 'inf']),
        (['run', '--grid', '3000x3000'], ['--grid', '3000']),
        (['run', '--seed', '-1'], ['--seed', '-1']),
        (['run', '--seed', '2.5'], ['--seed', '2.5']),
        (['hil', '--seed', '-1'], ['--seed', '-1']),
        (
            ['sweep', '--engine', 'mujoco', '--engine', 'mujoco', '--dry-run'],
            ['--engine', 'twice'],
        ),
        (['stress', '--engine', 'bullet', '--engine', 'bullet', '--list'], ['--engine', 'twice']),
        (['trajectory', '--rate', '1e9'], ['--rate']),
    ],
)
def test_cli_refuses_bad_values_before_any_work(capsys, tmp_path, monkeypatch, argv, words):
    monkeypatch.chdir(tmp_path)  # a run that slipped through would write results/ here
    code, out, err = run_main(capsys, cli.main, argv)
    assert_one_line(code, err, *words)
    assert not (tmp_path / 'results').exists()


@pytest.mark.parametrize(
    'argv,words',
    [
        (['run', '--engine', 'mujoco', '--engine', 'mujoco'], ['--engine', 'mujoco']),
        (['run', '--grid', '3000x3000'], ['--grid', '3000']),
    ],
)
def test_cli_refusals_in_a_real_process(tmp_path, argv, words):
    result = subprocess.run(
        [sys.executable, '-m', 'cloth_bench_ros.cli', *argv],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={**os.environ, 'PYTHONPATH': str(REPO)},
    )
    assert_one_line(result.returncode, result.stderr, *words)
    assert result.stdout == '' and not (tmp_path / 'results').exists()


def test_presets_dir_without_the_engine_file_is_refused(capsys, tmp_path):
    code, _, err = run_main(capsys, cli.main, ['run', '--presets', str(tmp_path)])
    assert_one_line(code, err, str(tmp_path), 'mujoco.yaml')


# --------------------------------------------------------------------- CLI: results not lost


@pytest.mark.parametrize('make', ['file', 'under_a_file'])
def test_unusable_output_is_found_before_the_run(capsys, tmp_path, make):
    blocker = tmp_path / 'summary.json'
    blocker.write_text('{"kept": true}\n')
    output = blocker if make == 'file' else blocker / 'run'
    code, out, err = run_main(capsys, cli.main, ['run', '--grid', '4x4', '--output', str(output)])
    assert_one_line(code, err, '--output', str(output))
    assert 'cloth-bench run:' not in out  # refused before the run, not after it
    assert blocker.read_text() == '{"kept": true}\n'


def test_existing_results_are_intact_after_a_refused_run(capsys, tmp_path):
    out_dir = tmp_path / 'run'
    out_dir.mkdir()
    (out_dir / 'summary.json').write_text('{"old": 1}\n')
    before = tree_digest(out_dir)
    code, _, err = run_main(
        capsys, cli.main, ['run', '--output', str(out_dir), '--set', 'mujoco.substeps=2.7']
    )
    assert_one_line(code, err, 'substeps')
    assert tree_digest(out_dir) == before


# ---------------------------------------------------------------------------- metadata values


def _bag_with_metadata_edit(tmp_path: Path, old: str, new: str) -> Path:
    bag = tmp_path / 'edited'
    shutil.copytree(BUNDLED, bag)
    mcap = next(bag.glob('*.mcap'))
    mcap.rename(bag / 'edited_0.mcap')
    meta = (bag / 'metadata.yaml').read_text()
    assert old in meta
    (bag / 'metadata.yaml').write_text(meta.replace(old, new).replace(mcap.name, 'edited_0.mcap'))
    return bag


def test_negative_change_of_phase_frame_in_a_bag_is_refused(capsys, tmp_path):
    bag = _bag_with_metadata_edit(
        tmp_path,
        "cloth_bench.change_of_phase_frame: '104'",
        "cloth_bench.change_of_phase_frame: '-5'",
    )
    run = ['run', '--grid', '4x4', '--bag', str(bag), '--output', str(tmp_path / 'o')]
    for argv in (['bag', 'info', str(bag)], run):
        code, out, err = run_main(capsys, cli.main, argv)
        assert_one_line(code, err, str(bag), 'change_of_phase_frame', '-5')
        assert 'CD_d' not in out  # never scored as "nothing, status ok"


# ------------------------------------------------------------------------------ node parameters


@pytest.mark.parametrize(
    'main,params,words',
    [
        (simulator.main, ['grid_nx:=-3', 'grid_nz:=8'], ['simulator', 'grid_nx', '-3']),
        (simulator.main, ['grid_nx:=1', 'grid_nz:=8'], ['simulator', 'grid_nx']),
        (simulator.main, ['grid_nx:=6'], ['simulator', 'grid_nz']),
        (simulator.main, ["engine_params:='{mass: '"], ['simulator', 'engine_params', 'YAML']),
        (simulator.main, ["engine_params:='[0.4]'"], ['simulator', 'engine_params', 'mapping']),
        (simulator.main, ["engine_params:='{substeps: 2.7}'"], ['substeps', '2.7']),
        (simulator.main, ["engine_params:='{mass: true}'"], ['mass', 'True']),
        (simulator.main, ['seed:=-1'], ['simulator', 'seed', '-1']),
        (simulator.main, ['rate_hz:=1000000000.0'], ['simulator', 'rate_hz']),
        (simulator.main, ['presets_dir:=no/such/dir'], ['no/such/dir']),
        (
            recorder.main,
            ['bag:=' + str(BUNDLED), 'clock:=wall', 'rate_factor:=.inf'],
            ['recorder', 'rate_factor', 'inf'],
        ),
        (
            recorder.main,
            ['bag:=' + str(BUNDLED), 'rate_factor:=-2.0'],
            ['recorder', 'rate_factor', '-2'],
        ),
        (
            recorder.main,
            ['bag:=' + str(BUNDLED), 'time_offset:=.nan'],
            ['recorder', 'time_offset', 'nan'],
        ),
        (
            recorder.main,
            ['bag:=' + str(BUNDLED), 'start_offset:=1.0e+300'],
            ['recorder', 'start_offset'],
        ),
        (
            evaluator.main,
            ['change_of_phase_frame:=-5'],
            ['evaluator', 'change_of_phase_frame', '-5'],
        ),
        (evaluator.main, ['seed:=-2'], ['evaluator', 'seed', '-2']),
        (
            evaluator.main,
            ['engines:=[mujoco, mujoco]'],
            ['evaluator', 'engines', 'mujoco', 'twice'],
        ),
        (
            trajectory_publisher.main,
            ['engines:=[bullet, bullet]'],
            ['trajectory_publisher', 'engines', 'twice'],
        ),
        (
            evaluator.main,
            ['output_dir:=/dev/null/run'],
            ['evaluator', 'output_dir', '/dev/null/run'],
        ),
        (
            trajectory_publisher.main,
            ['rate_hz:=-100.0'],
            ['trajectory_publisher', 'rate_hz', '-100'],
        ),
    ],
)
def test_node_refuses_bad_parameter_naming_it(capsys, main, params, words):
    argv = ['node', '--ros-args'] + [a for p in params for a in ('-p', p)]
    code, _, err = run_main(capsys, main, argv)
    assert_one_line(code, err, *words)


# ------------------------------------------------------------------------------------ importer


def _dataset(root: Path, folder: str = 'cotton_rag_0', primitive: str = 'quasi_static') -> Path:
    cloud = root / folder / primitive / 'cloud'
    cloud.mkdir(parents=True)
    return cloud


@pytest.mark.parametrize(
    'name,edit,words',
    [
        (
            '00000.ply',
            lambda b: b.replace(b'element vertex 3\n', b'element vertex -5\n'),
            ['element vertex', '-5'],
        ),
        (
            '00000.ply',
            lambda b: b.replace(b'element vertex 3\n', b'element vertex 2.5\n'),
            ['element vertex', '2.5'],
        ),
        ('00000.pcd', lambda b: b.replace(b'COUNT 1 1 1 1', b'COUNT 0 1 1 1'), ['COUNT', '0']),
        ('00000.pcd', lambda b: b.replace(b'POINTS 3', b'POINTS -3'), ['POINTS', '-3']),
        ('00000.pcd', lambda b: b.replace(b'POINTS 3', b'POINTS 7'), ['POINTS 7', 'WIDTH']),
        ('00000.pcd', lambda b: b.replace(b'FIELDS x y z rgb', b'FIELDS x y x rgb'), ['twice']),
    ],
)
def test_import_refuses_malformed_cloud_headers(capsys, tmp_path, name, edit, words):
    cloud = _dataset(tmp_path / 'data')
    pts = np.arange(9, dtype=float).reshape(3, 3)
    (write_ply if name.endswith('.ply') else lambda p, x: write_pcd(p, x, as_text=False))(
        cloud / name, pts
    )
    (cloud / name).write_bytes(edit((cloud / name).read_bytes()))
    argv = ['import', str(tmp_path / 'data'), '--output', str(tmp_path / 'out'), '--no-progress']
    code, _, err = run_main(capsys, cli.main, argv)
    assert_one_line(code, err, name, *words)
    assert not any((tmp_path / 'out').iterdir()) if (tmp_path / 'out').exists() else True


def test_import_refuses_two_folders_mapping_to_one_trial(capsys, tmp_path):
    for folder in ('cotton_rag_1', 'cotton_rag_01'):
        write_ply(_dataset(tmp_path / 'data', folder) / '00000.ply', np.zeros((2, 3)))
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'keep.txt').write_text('kept')
    code, _, err = run_main(
        capsys, cli.main, ['import', str(tmp_path / 'data'), '--output', str(out), '--no-progress']
    )
    assert_one_line(code, err, 'cotton_rag_1', 'cotton_rag_01', 'towel_1_quasi_static')
    assert sorted(p.name for p in out.iterdir()) == ['keep.txt']


# --------------------------------------------------------------------------------------- synth


def _tiny_reference() -> synth.SynthConfig:
    return synth.reference_config(
        'towel',
        'dynamic',
        grid=(5, 7),
        rate_hz=300.0,
        duration=0.2,
        sensor=virtual_camera.Sensor(
            camera=virtual_camera.Camera(width=64, height=36), max_points=100
        ),
    )


def test_failed_synth_leaves_no_bag_and_an_old_bag_intact(tmp_path):
    config = _tiny_reference()

    def fail_at_frame_2(k, vertices, points):
        if k == 2:
            raise synth.SynthError('reference failed at frame 2')

    out = tmp_path / 'bag'
    with pytest.raises(synth.SynthError):
        synth.write_synthetic_bag(config, out, on_frame=fail_at_frame_2)
    assert (
        not out.exists() and list(tmp_path.iterdir()) == []
    )  # nothing half-written, nothing staged
    synth.write_synthetic_bag(config, out)
    before = tree_digest(out)
    assert BagReader(out).message_counts['/cloth_bench/real/cloud'] == config.frame_count
    with pytest.raises(synth.SynthError):
        synth.write_synthetic_bag(config, out, overwrite=True, on_frame=fail_at_frame_2)
    assert tree_digest(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ['bag']


def test_synth_into_an_existing_bag_is_refused_before_simulating(capsys, tmp_path):
    out = tmp_path / 'bag'
    out.mkdir()
    (out / 'metadata.yaml').write_text('old\n')
    code, _, err = run_main(capsys, cli.main, ['synth', '--output', str(out), '--no-progress'])
    assert_one_line(code, err, str(out), 'already exists')
    assert (out / 'metadata.yaml').read_text() == 'old\n'


# -------------------------------------------------------------------------- recorder, full disk

FLOOD = '''
import sys
import numpy as np
from cloth_bench_ros.nodes.common import run_nodes
from cloth_bench_ros.nodes.recorder import Recorder
from cloth_bench_ros.core.pointcloud2 import create_cloud_xyz32
from cloth_bench_ros.runtime import Header, Node, PointCloud2, PointField, Time, make_qos


class Flood(Node):
    """Publishes incompressible clouds until the recorder stops the process."""

    def __init__(self):
        super().__init__("flood", namespace="cloth_bench")
        self.pub = self.create_publisher(PointCloud2, "sim/cloud", make_qos(10))
        self.rng = np.random.default_rng(0)
        self.k = 0
        self.done = True
        self.timer = self.create_timer(0.001, self.tick)

    def tick(self):
        for _ in range(10):
            header = Header(stamp=Time(nanoseconds=1000 + self.k).to_msg(), frame_id="world")
            points = self.rng.normal(size=(500, 3))
            self.pub.publish(create_cloud_xyz32(header, points, PointCloud2, PointField))
            self.k += 1
            if self.k > 20000:
                raise SystemExit("the disk never filled")


sys.exit(run_nodes([Flood, Recorder], sys.argv[1:]))
'''


def _record_until_full(tmp_path: Path, out: Path, wrap: list[str] | None = None, preexec=None):
    script = tmp_path / 'flood.py'
    script.write_text(FLOOD)
    args = [
        sys.executable,
        str(script),
        '--ros-args',
        '-p',
        'mode:=record',
        '-p',
        f'output:={out}',
        '-p',
        "record_topics:=['sim/cloud:sensor_msgs/msg/PointCloud2']",
    ]
    env = {**os.environ, 'PYTHONPATH': str(REPO)}
    return subprocess.run(
        (wrap or []) + args,
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=preexec,
        env=env,
        cwd=tmp_path,
    )


def _check_stopped_recording(result, out: Path, complete: bool) -> None:
    line = assert_one_line(result.returncode, result.stderr, 'recorder', str(out))
    report = [row for row in result.stdout.splitlines() if row.startswith('recorder:')]
    assert len(report) == 1, result.stdout
    received, written = (int(w) for w in report[0].replace(',', '').split() if w.isdigit())
    assert f'keeps the {written} messages' in line
    assert 0 < written <= received
    reader = BagReader(out)  # metadata.yaml is there and agrees with what the file holds
    assert (out / 'metadata.yaml').is_file() and reader.complete == complete
    assert reader.message_counts['/cloth_bench/sim/cloud'] == written
    assert sum(1 for _ in reader.raw_messages()) == written
    assert not (out / recorder.RESERVE_NAME).exists()


def test_recorder_write_error_keeps_counts_and_metadata(tmp_path):
    """A real write error from the kernel (RLIMIT_FSIZE: EFBIG) in the middle of a chunk."""

    def limit_file_size():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (3_000_000, 3_000_000))

    out = tmp_path / 'rec'
    result = _record_until_full(tmp_path, out, preexec=limit_file_size)
    assert 'File too large' in result.stderr
    with pytest.warns(Warning, match='truncated|damage|summary'):
        _check_stopped_recording(result, out, complete=False)


def _can_mount_tmpfs(tmp_path: Path) -> bool:
    if shutil.which('unshare') is None:
        return False
    probe = subprocess.run(
        ['unshare', '-rm', 'sh', '-c', f'mount -t tmpfs -o size=1m tmpfs {tmp_path}'],
        capture_output=True,
    )
    return probe.returncode == 0


def test_recorder_on_a_full_tmpfs_stops_with_a_complete_bag(tmp_path):
    """A real full filesystem: an 8 MiB tmpfs in a private mount namespace (no root needed)."""
    disk = tmp_path / 'disk'
    disk.mkdir()
    if not _can_mount_tmpfs(disk):
        pytest.skip('cannot mount a tmpfs here (no unprivileged user namespaces)')
    out = disk / 'rec'
    script = tmp_path / 'flood.py'
    script.write_text(FLOOD)
    # The tmpfs lives only in the child's namespace: copy the bag out before it ends.
    keep = tmp_path / 'kept'
    inner = (
        f'mount -t tmpfs -o size=8m tmpfs {disk} && {sys.executable} {script} --ros-args -p'
        f' mode:=record -p output:={out} -p'
        f' "record_topics:=[\'sim/cloud:sensor_msgs/msg/PointCloud2\']"; status=$?; cp -r {out}'
        f' {keep}; exit $status'
    )
    result = subprocess.run(
        ['unshare', '-rm', 'sh', '-c', inner],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, 'PYTHONPATH': str(REPO)},
        cwd=tmp_path,
    )
    assert 'disk nearly full' in result.stderr, result.stderr
    result.stderr = result.stderr.replace(str(out), str(keep))
    _check_stopped_recording(result, keep, complete=True)


def test_synth_rate_must_put_frames_on_steps(capsys, tmp_path, monkeypatch):
    out = tmp_path / 'bag'
    code, _, err = run_main(capsys, cli.main, ['synth', '--output', str(out), '--rate', '1000'])
    assert_one_line(code, err, '1000 Hz', 'not a multiple of 30 fps')
    assert not out.exists()
    made = []  # the configuration the bag would be made from (minutes to simulate at 31 x 43)

    def keep_config(config, *args):
        made.append(config)
        return out

    monkeypatch.setattr(synth, 'write_synthetic_bag', keep_config)
    assert cli.main(['synth', '--output', str(out), '--rate', '1800', '--no-progress']) == 0
    assert made[0].rate_hz == 1800.0 and made[0].steps_per_frame == 60
