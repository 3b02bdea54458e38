"""
Synthetic reference bags: visibility, noise, outlier removal, the bag, acceptance order.

Z-buffer visibility, sensor noise, outlier removal, the bag, and the acceptance ordering (the
reference model scores at the noise floor, wrong models clearly worse).
"""

from __future__ import annotations

from dataclasses import replace

from cloth_bench_ros.core import cleaning, scene
from cloth_bench_ros.core.metrics import chamfer_l1
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import sample_quintic
from cloth_bench_ros.data import BagReader, CLOUD_TOPIC, synth, virtual_camera
from cloth_bench_ros.data.importer import CLOTH_NAMES
from cloth_bench_ros.engines import engine_class
from cloth_bench_ros.paths import bundled_bag
import numpy as np
import pytest

SMALL = virtual_camera.Camera(width=320, height=180)  # the same optics, 4x coarser pixels
EXACT = virtual_camera.DepthNoise(sigma0=0.0, sigma2=0.0, flying_fraction=0.0, depth_step=0.0)


def plane(
    x: tuple[float, float], z: tuple[float, float], y: float, flip: bool = False
) -> np.ndarray:
    """Two triangles (2, 3, 3) of an x-z rectangle at depth y facing the camera (or away)."""
    (x0, x1), (z0, z1) = x, z
    tris = virtual_camera._quad((x0, y, z0), (x1, y, z0), (x1, y, z1), (x0, y, z1))
    return tris[:, ::-1] if flip else tris


def back_project_all(camera: virtual_camera.Camera, depth: np.ndarray) -> np.ndarray:
    v, u = np.nonzero(np.isfinite(depth))
    return camera.back_project(u.astype(float), v.astype(float), depth[v, u])


# ------------------------------------------------------------------------- camera and z-buffer


def test_camera_is_the_azure_kinect_of_the_scene():
    cam = virtual_camera.Camera()
    assert (cam.width, cam.height) == (1280, 720)
    assert cam.focal == pytest.approx(640.0)  # hfov 90 deg
    # The cloth's rest centre projects near the image centre; depth = distance along -y.
    uv, z = cam.project(np.array([[0.25, 0.0, 0.70]]))
    assert uv[0] == pytest.approx(cam.center)
    assert z[0] == pytest.approx(1.80)
    # Image right is world -x (the camera looks along -y), image down is world -z.
    uv2, _ = cam.project(np.array([[0.0, 0.0, 0.5]]))
    assert uv2[0, 0] > uv[0, 0] and uv2[0, 1] > uv[0, 1]
    back = cam.back_project(uv2[:, 0], uv2[:, 1], np.array([1.8]))
    assert back[0] == pytest.approx([0.0, 0.0, 0.5])


@pytest.mark.parametrize('flip_front', [False, True])
def test_zbuffer_keeps_only_the_visible_surface(flip_front):
    front = plane((0.0, 0.5), (0.5, 1.0), 0.0, flip=flip_front)  # both faces must render
    back = plane((-0.2, 0.7), (0.4, 1.1), -0.3)
    depth, ids = virtual_camera.rasterize(SMALL, np.concatenate([back, front]))
    pts = back_project_all(SMALL, depth)
    assert len(pts) > 1000
    in_front = (pts[:, 0] > 0.01) & (pts[:, 0] < 0.49) & (pts[:, 2] > 0.51) & (pts[:, 2] < 0.99)
    # Pixels whose ray meets the front plane see only it; the back plane shows only around it.
    assert np.allclose(pts[in_front, 1], 0.0, atol=1e-9)
    on_back = np.isclose(pts[:, 1], -0.3, atol=1e-9)
    assert on_back.sum() > 100 and (on_back | np.isclose(pts[:, 1], 0.0, atol=1e-9)).all()
    # The back plane's hidden part, seen through the front plane's silhouette, never shows.
    shadow = SMALL.project(pts[on_back])[0]
    front_uv = SMALL.project(front.reshape(-1, 3))[0]
    lo, hi = front_uv.min(axis=0) + 1, front_uv.max(axis=0) - 1
    assert not np.all((shadow > lo) & (shadow < hi), axis=1).any()
    assert set(np.unique(ids)) == {-1, 0, 1, 2, 3}


def test_zbuffer_depth_is_perspective_correct_on_a_slanted_triangle():
    tri = np.array([[[0.0, 0.3, 0.5], [0.5, -0.4, 0.5], [0.25, 0.0, 1.0]]])
    depth, _ = virtual_camera.rasterize(SMALL, tri)
    pts = back_project_all(SMALL, depth)
    a, b, c = tri[0]
    normal = np.cross(b - a, c - a)
    assert len(pts) > 50
    assert np.abs((pts - a) @ normal / np.linalg.norm(normal)).max() < 1e-9  # on the plane


# --------------------------------------------------------------------------------- the sensor


def test_depth_noise_is_as_configured():
    noise = virtual_camera.DepthNoise(
        sigma0=0.001, sigma2=0.0005, flying_fraction=0.0, depth_step=0.0
    )
    sensor = virtual_camera.Sensor(
        camera=SMALL, noise=noise, sor_std_ratio=50.0, max_points=10**9, resolution=0.0
    )
    rng = np.random.default_rng(1)
    pts = virtual_camera.observe(sensor, plane((-0.3, 0.8), (0.3, 1.2), 0.0), rng)  # facing it
    expected = 0.001 + 0.0005 * 1.80**2  # 2.62 mm: the Azure Kinect's 1.5-3 mm at 1.8 m
    assert len(pts) > 5000
    residual = pts[:, 1]  # depth error along the ray = along -y for this plane
    assert abs(residual.mean()) < 1e-4
    assert residual.std() == pytest.approx(expected, rel=0.05)
    # Depth comes in whole millimetres by default, as the Kinect's uint16 depth image.
    d, _ = virtual_camera.rasterize(SMALL, plane((0.0, 0.5), (0.5, 1.0), 0.0))
    cloth = np.isfinite(d)
    measured = virtual_camera.noisy_depth(d, cloth, virtual_camera.DepthNoise(), rng)[cloth]
    assert np.allclose(measured * 1000, np.round(measured * 1000), atol=1e-6)


def test_outlier_removal_drops_injected_outliers():
    rng = np.random.default_rng(2)
    inliers = np.column_stack(
        [rng.uniform(0, 0.5, 20000), rng.normal(0, 0.002, 20000), rng.uniform(0.3, 1.0, 20000)]
    )
    outliers = rng.uniform([-0.3, -0.3, 0.2], [0.8, 0.3, 1.3], (200, 3))
    outliers = outliers[np.abs(outliers[:, 1]) > 0.03]  # off the sheet
    kept = cleaning.remove_outliers(
        np.concatenate([inliers, outliers]), neighbors=20, std_ratio=2.0
    )
    off_sheet = np.abs(kept[:, 1]) > 0.03
    assert off_sheet.sum() <= 0.05 * len(outliers)
    assert (~off_sheet).sum() >= 0.95 * len(inliers)


def test_flying_pixels_appear_at_the_silhouette_and_are_mostly_cleaned():
    noise = virtual_camera.DepthNoise(flying_fraction=1.0)
    cloth = plane((0.0, 0.5), (0.3, 1.0), 0.0)
    background = virtual_camera.rasterize(SMALL, virtual_camera.background_triangles())

    def far(sor_std_ratio: float) -> int:
        sensor = virtual_camera.Sensor(
            camera=SMALL, noise=noise, sor_std_ratio=sor_std_ratio, max_points=10**9
        )
        pts = virtual_camera.observe(sensor, cloth, np.random.default_rng(3), background)
        return int((np.abs(pts[:, 1]) > 0.03).sum())

    raw, cleaned = far(1e6), far(2.0)
    assert raw > 20  # every silhouette pixel flies, between the cloth and the wall behind
    assert cleaned <= 0.3 * raw


def test_cloud_is_cropped_above_the_table():
    sensor = virtual_camera.Sensor(camera=SMALL, max_points=10**9)
    cloth = plane((0.0, 0.5), (0.0, 1.0), 0.0)  # reaches below the table top
    pts = virtual_camera.observe(
        sensor,
        cloth,
        np.random.default_rng(4),
        virtual_camera.rasterize(SMALL, virtual_camera.background_triangles()),
    )
    assert pts[:, 2].min() > scene.TABLE_TOP_Z
    assert pts[:, 2].min() < scene.TABLE_TOP_Z + 0.01


# ------------------------------------------------------------------------ the reference model


def test_reference_config_differs_from_the_models_under_test():
    tested = engine_class('mujoco').validate_params({})
    masses = {}
    for cloth in CLOTH_NAMES.values():
        for primitive, frames in (('dynamic', 132), ('quasi_static', 420)):
            cfg = synth.reference_config(cloth, primitive)
            assert cfg.frame_count == frames
            assert cfg.params['integrator'] != tested['integrator']
            assert cfg.grid != (ClothGrid().nx, ClothGrid().nz)
            assert cfg.steps_per_frame == 30
            assert cfg.provenance
            masses[cloth] = cfg.params['mass']
            # the tested 11 x 15 grid is nested in the reference grid
            fine = ClothGrid(*cfg.grid).vertices()
            assert np.allclose(
                synth.coarse_vertices(fine, cfg.grid, (11, 15)), ClothGrid().vertices()
            )
    assert masses['towel'] > masses['chequered'] > masses['linen']


def test_bad_requests_are_one_line_errors():
    with pytest.raises(synth.SynthError, match="unknown cloth 'silk'"):
        synth.reference_config('silk', 'dynamic')
    with pytest.raises(ValueError, match='unknown primitive'):
        synth.reference_config('towel', 'fling')
    with pytest.raises(synth.SynthError, match='not a multiple of 30 fps'):
        synth.reference_config('towel', 'dynamic', rate_hz=1000.0).steps_per_frame
    with pytest.raises(ValueError, match='not nested'):
        synth.coarse_vertices(ClothGrid(25, 35).vertices(), (25, 35), (11, 15))


def quick(
    cloth: str = 'towel', primitive: str = 'dynamic', duration: float = 1.0, **kw
) -> synth.SynthConfig:
    """Return a cheap reference: coarse grid, 300 Hz, a low-resolution camera, a short piece."""
    cfg = synth.reference_config(cloth, primitive, grid=(11, 15), rate_hz=300.0, duration=duration)
    return replace(cfg, sensor=replace(cfg.sensor, camera=SMALL), **kw)


def test_synthetic_bag_reads_back(tmp_path):
    cfg = quick('linen', 'dynamic', duration=0.2)
    out = synth.write_synthetic_bag(cfg, tmp_path / 'linen_dynamic')
    reader = BagReader(out)
    clouds = list(reader.clouds(CLOUD_TOPIC))
    assert [s for s, _ in clouds] == [round(k * 1e9 / 30) for k in range(6)]
    assert all(200 < len(p) <= cfg.sensor.max_points for _, p in clouds)
    trial = reader.trial
    # 0.2 s of the fling never reaches the table: no change of phase (runs then score every frame).
    assert (trial.cloth, trial.trial, trial.primitive, trial.change_of_phase_frame) == (
        'linen',
        0,
        'dynamic',
        None,
    )
    assert trial.source.startswith(
        'synthetic: reference mujoco shell cloth 11x15, integrator discrete'
    )
    assert reader.stats.irregular_intervals == 0
    # The same seed gives the same bag.
    again = list(synth.render_frames(cfg))
    assert all(np.allclose(a, b, atol=1e-6) for (_, a), (_, b) in zip(clouds, again))


def mean_cd(vertex_frames: list[np.ndarray], clouds: list[np.ndarray]) -> float:
    return float(np.mean([chamfer_l1(v, p) for v, p in zip(vertex_frames, clouds)]))


@pytest.mark.slow
def test_reference_scores_at_the_noise_floor_and_wrong_models_clearly_worse():
    cfg = quick('towel', 'dynamic', duration=1.2)
    frames = list(synth.synthetic_frames(cfg))
    own = [v for _, v, _ in frames]
    clouds = [p for _, _, p in frames]
    # Frame k is the state at t = k / 30 s of the quintic part: the corners sit on the grippers.
    grippers = sample_quintic('dynamic', cfg.fps)
    assert len(own) == 36
    assert np.allclose([v[0] for v in own], grippers.left[:36], atol=1e-9)
    assert np.allclose([v[10] for v in own], grippers.right[:36], atol=1e-9)

    half = replace(cfg, params={**cfg.params, 'mass': cfg.params['mass'] / 2})
    half_mass = [v for _, v in synth.simulate_reference(half)]
    shift = round(0.2 * cfg.fps)  # the state 0.2 s late
    scored = slice(shift, None)

    cd_own = mean_cd(own[scored], clouds[scored])
    cd_half = mean_cd(half_mass[scored], clouds[scored])
    cd_late = mean_cd(own[:-shift], clouds[scored])

    # Noise floor: depth noise plus the spacing of max_points random samples over the cloth.
    sigma = float(cfg.sensor.noise.sigma(1.8))
    spacing = np.sqrt(scene.CLOTH_WIDTH * scene.CLOTH_LENGTH / cfg.sensor.max_points)
    floor = sigma + spacing
    assert cd_own < floor, (cd_own, floor)
    assert cd_half > 2 * cd_own, (cd_half, cd_own)
    assert cd_late > 3 * cd_own, (cd_late, cd_own)


# ------------------------------------------------------------------------------ bundled bags


def test_bundled_bags_are_complete_and_within_budget():
    total = 0
    for cloth in CLOTH_NAMES.values():
        for primitive, frames in (('dynamic', 132), ('quasi_static', 420)):
            path = bundled_bag(cloth, primitive)
            reader = BagReader(path)
            stamps = [s for s, _ in reader.clouds(CLOUD_TOPIC)]
            assert stamps == [round(k * 1e9 / 30) for k in range(frames)], path
            assert reader.complete and reader.stats.nan_points_dropped == 0
            trial = reader.trial
            assert (trial.cloth, trial.trial, trial.primitive) == (cloth, 0, primitive)
            # The first table contact in the clouds (test_change_of_phase.py checks it on every
            # dynamic bag).
            assert (trial.change_of_phase_frame is None) == (primitive == 'quasi_static')
            assert trial.source.startswith(
                'synthetic: reference mujoco shell cloth 31x43, integrator discrete'
            )
            total += sum(f.stat().st_size for f in path.iterdir())
    assert total <= 25_000_000


def test_bundled_newton_reference_bags_for_the_towel():
    from cloth_bench_ros.studies.cross_reference import reference_bag

    for primitive, frames in (('dynamic', 132), ('quasi_static', 420)):
        path = reference_bag('towel', primitive, 'newton-vbd')
        reader = BagReader(path)
        stamps = [s for s, _ in reader.clouds(CLOUD_TOPIC)]
        assert stamps == [round(k * 1e9 / 30) for k in range(frames)], path
        assert reader.complete and reader.stats.nan_points_dropped == 0
        trial = reader.trial
        assert (trial.cloth, trial.primitive) == ('towel', primitive)
        assert trial.source.startswith(
            'synthetic: reference newton vbd cloth 31x43, 2400 Hz, self-collision on'
        )
    bags = bundled_bag('towel', 'dynamic').parent
    assert (
        sum(f.stat().st_size for f in bags.rglob('*') if f.is_file()) <= 40_000_000
    )  # all of bags/
