"""The dataset importer on a PLY/PCD tree made by the tests, read back from real bags."""

from __future__ import annotations

from pathlib import Path

from cloth_bench_ros.data import BagReader, CLOUD_TOPIC
from cloth_bench_ros.data.importer import (
    CloudFileError,
    find_trials,
    import_dataset,
    read_cloud_file,
)
import numpy as np
import pytest


def write_ply(path: Path, pts: np.ndarray, xyz_type: str = 'float', extra: bool = True) -> None:
    """Binary little-endian PLY: x, y, z (+ colour and a normal when extra) and a face element."""
    np_type = {'float': '<f4', 'double': '<f8'}[xyz_type]
    fields = [('x', np_type), ('y', np_type), ('z', np_type)]
    if extra:
        fields = [('red', 'u1'), *fields, ('green', 'u1'), ('blue', 'u1'), ('nx', '<f4')]
    table = np.zeros(len(pts), dtype=fields)
    for i, c in enumerate('xyz'):
        table[c] = pts[:, i]
    props = ''.join(
        f'property {dict(u1="uchar", **{"<f4": "float", "<f8": "double"})[t]} {n}\n'
        for n, t in fields
    )
    header = (
        'ply\nformat binary_little_endian 1.0\ncomment made by the test\nelement vertex'
        f' {len(pts)}\n{props}element face 0\nproperty list uchar int vertex_indices\nend_header\n'
    )
    path.write_bytes(header.encode() + table.tobytes())


def write_pcd(path: Path, pts: np.ndarray, as_text: bool) -> None:
    """PCD v0.7 with x y z rgb, DATA ascii or binary."""
    rgb = np.arange(len(pts), dtype=np.uint32)
    header = (
        '# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\n'
        f'TYPE F F F U\nCOUNT 1 1 1 1\nWIDTH {len(pts)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n'
        f'POINTS {len(pts)}\nDATA {"ascii" if as_text else "binary"}\n'
    )
    if as_text:
        body = ''.join(
            f'{x!r} {y!r} {z!r} {c}\n'
            for (x, y, z), c in zip(pts.astype(np.float32).tolist(), rgb)
        )
        path.write_bytes(header.encode() + body.encode())
    else:
        table = np.zeros(
            len(pts), dtype=[('x', '<f4'), ('y', '<f4'), ('z', '<f4'), ('rgb', '<u4')]
        )
        for i, c in enumerate('xyz'):
            table[c] = pts[:, i]
        table['rgb'] = rgb
        path.write_bytes(header.encode() + table.tobytes())


# (folder, primitive, writer kind, frames)
TREE = [
    ('cotton_rag_0', 'dynamic', 'ply', 7),
    ('linen_rag_1', 'quasi_static', 'pcd-binary', 5),
    ('chequered_rag_2', 'dynamic', 'pcd-ascii', 4),
]


def make_tree(root: Path) -> dict[tuple[str, str], list[np.ndarray]]:
    rng = np.random.default_rng(11)
    made = {}
    for folder, primitive, kind, n in TREE:
        cloud = root / folder / primitive / 'cloud'
        cloud.mkdir(parents=True)
        frames = []
        for k in range(n):
            pts = rng.uniform(-1, 1, (50 + 10 * k, 3))
            if k == 2:
                pts[4] = np.nan  # organised clouds carry NaN points; they must survive import
            if kind == 'ply':
                write_ply(cloud / f'{k:05d}.ply', pts, xyz_type='double' if k % 2 else 'float')
            else:
                write_pcd(cloud / f'{k:05d}.pcd', pts, as_text=kind == 'pcd-ascii')
            frames.append(pts)
        made[(folder, primitive)] = frames
    (root / 'README.txt').write_text('not a trial')
    (root / 'cotton_rag_0' / 'dynamic' / 'cloud' / 'notes.txt').write_text('ignored')
    return made


def test_import_tree_frames_match_files_point_for_point(tmp_path: Path) -> None:
    made = make_tree(tmp_path / 'data')
    bags = import_dataset(tmp_path / 'data', tmp_path / 'bags', progress=False)
    assert [b.name for b in bags] == [
        'chequered_2_dynamic',
        'towel_0_dynamic',
        'linen_1_quasi_static',
    ]
    assert sorted(p.name for p in (tmp_path / 'bags').iterdir()) == sorted(b.name for b in bags)
    expected = {
        'towel_0_dynamic': ('cotton_rag_0', 'dynamic', 99),
        'linen_1_quasi_static': ('linen_rag_1', 'quasi_static', None),
        'chequered_2_dynamic': ('chequered_rag_2', 'dynamic', 99),
    }
    for bag in bags:
        folder, primitive, cop = expected[bag.name]
        reader = BagReader(bag)
        trial = reader.trial
        assert (trial.primitive, trial.change_of_phase_frame, trial.fps) == (primitive, cop, 30.0)
        assert trial.source == f'imported from {folder}/{primitive}'
        stamps, nan_rows = [], 0
        raw = [(t, msg) for _, t, msg in reader.messages(CLOUD_TOPIC)]
        from cloth_bench_ros.core.pointcloud2 import read_xyz

        for k, ((t, msg), ref) in enumerate(zip(raw, made[(folder, primitive)], strict=True)):
            stamps.append(t)
            got = read_xyz(msg)  # everything stored, NaN included, in file order
            np.testing.assert_array_equal(got, ref.astype(np.float32).astype(np.float64))
            nan_rows += int(np.isnan(ref).any(axis=1).sum())
        assert stamps == [round(k * 1e9 / 30) for k in range(len(raw))]
        frames = list(reader.clouds())
        assert len(frames) == len(raw) and reader.stats.nan_points_dropped == nan_rows == 1
        assert reader.stats.irregular_intervals == 0


def test_transform_is_applied_and_recorded(tmp_path: Path) -> None:
    made = make_tree(tmp_path / 'data')
    angle = np.pi / 2
    t = np.array(
        [
            [np.cos(angle), -np.sin(angle), 0, 0.1],
            [np.sin(angle), np.cos(angle), 0, -0.2],
            [0, 0, 1, 0.3],
            [0, 0, 0, 1],
        ]
    )
    bags = import_dataset(tmp_path / 'data', tmp_path / 'bags', transform=t, progress=False)
    reader = BagReader(bags[1])  # towel_0_dynamic
    np.testing.assert_allclose(reader.trial.transform, t)
    ref = made[('cotton_rag_0', 'dynamic')][0]
    _, pts = next(iter(reader.clouds()))
    np.testing.assert_allclose(pts, ref @ t[:3, :3].T + t[:3, 3], atol=1e-6)


@pytest.mark.slow
def test_readers_agree_with_open3d(tmp_path: Path) -> None:
    o3d = pytest.importorskip('open3d')
    pts = np.random.default_rng(4).uniform(-2, 2, (300, 3))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    for name, ascii_ in (('a.ply', False), ('b.pcd', False), ('c.pcd', True), ('d.ply', True)):
        assert o3d.io.write_point_cloud(str(tmp_path / name), cloud, write_ascii=ascii_)
        got = read_cloud_file(tmp_path / name)
        if ascii_:  # open3d's ASCII PLY writer prints 6 significant digits
            np.testing.assert_allclose(got, pts, rtol=0, atol=1e-5)
        else:  # binary: exactly what open3d stored, float32 or float64
            assert np.array_equal(got, pts) or np.array_equal(got, pts.astype(np.float32)), name


def test_bad_inputs_give_one_line_naming_the_input(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match='is not a directory'):
        import_dataset(tmp_path / 'missing', tmp_path / 'out', progress=False)
    (tmp_path / 'empty').mkdir()
    with pytest.raises(ValueError, match='has no <cloth>_rag_<trial>'):
        import_dataset(tmp_path / 'empty', tmp_path / 'out', progress=False)
    make_tree(tmp_path / 'data')
    with pytest.raises(ValueError, match='4x4'):
        import_dataset(tmp_path / 'data', tmp_path / 'out', transform=np.eye(3), progress=False)
    bad = tmp_path / 'data' / 'linen_rag_1' / 'quasi_static' / 'cloud' / '00003.pcd'
    bad.write_bytes(bad.read_bytes()[:-40])
    with pytest.raises(CloudFileError) as exc:
        import_dataset(tmp_path / 'data', tmp_path / 'out', progress=False)
    assert (
        '\n' not in str(exc.value)
        and '00003.pcd' in str(exc.value)
        and 'truncated' in str(exc.value)
    )
    # nothing half-written is left behind; bags finished before the error remain
    assert sorted(p.name for p in (tmp_path / 'out').iterdir()) == [
        'chequered_2_dynamic',
        'towel_0_dynamic',
    ]
    with pytest.raises(ValueError, match='already exists'):
        import_dataset(tmp_path / 'data', tmp_path / 'out', progress=False)


def test_cloud_file_errors(tmp_path: Path) -> None:
    (tmp_path / 'x.ply').write_bytes(b'not a ply')
    head = 'VERSION 0.7\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nPOINTS 0\n'
    (tmp_path / 'y.pcd').write_text(head + 'FIELDS a b c\nDATA binary\n')
    (tmp_path / 'z.pcd').write_text(head + 'FIELDS x y z\nDATA binary_compressed\n')
    (tmp_path / 'w.xyz').write_text('')
    cases = (
        ('x.ply', 'not a PLY'),
        ('y.pcd', 'no x/y/z field'),
        ('z.pcd', 'unsupported PCD DATA'),
        ('w.xyz', 'not a .ply'),
    )
    for name, what in cases:
        with pytest.raises(CloudFileError) as exc:
            read_cloud_file(tmp_path / name)
        assert name in str(exc.value) and what in str(exc.value) and '\n' not in str(exc.value)


def test_duplicate_frame_formats(tmp_path: Path) -> None:
    cloud = tmp_path / 'linen_rag_0' / 'dynamic' / 'cloud'
    cloud.mkdir(parents=True)
    write_ply(cloud / '00000.ply', np.zeros((1, 3)))
    write_pcd(cloud / '00000.pcd', np.zeros((1, 3)), as_text=True)
    with pytest.raises(ValueError, match='both'):
        find_trials(tmp_path)


def test_import_can_clean_through_the_one_cleaning_module(tmp_path: Path) -> None:
    from cloth_bench_ros.core.cleaning import clean, CleaningConfig

    made = make_tree(tmp_path / 'data')
    config = CleaningConfig(
        (-0.5, -0.5, -0.5), (0.5, 0.5, 0.5), table_plane=False, sor_neighbors=0
    )
    bags = import_dataset(tmp_path / 'data', tmp_path / 'bags', progress=False, cleaning=config)
    reader = BagReader(bags[1])  # towel_0_dynamic
    for (_, pts), ref in zip(reader.clouds(), made[('cotton_rag_0', 'dynamic')], strict=True):
        expected = clean(ref, config)
        assert 0 < len(pts) == len(expected) < len(ref)
        np.testing.assert_allclose(pts, expected, atol=1e-6)
