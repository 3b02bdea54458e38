"""
Synthetic reference bags: a high-resolution reference cloth seen by a virtual Azure Kinect.

A reference simulation (config/synth.yaml: finer grid and another integrator than the models under
test) runs along the full trajectory; at every 30 fps frame its mesh is rasterised into a z-buffer
by a pinhole camera placed as docs/benchmark.md section 1 says, so that only the surfaces the
camera sees survive. The depth image gets Azure-Kinect-like noise and flying pixels at the
silhouette, is back-projected to the world frame, cropped to the cloth above the table, cleaned by
statistical outlier removal (open3d) and randomly subsampled to a point budget: partial, noisy
clouds, far denser than the simulated mesh, like the real ones.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
import math
from pathlib import Path
from typing import Any

from cloth_bench_ros.core import cleaning, scene
from cloth_bench_ros.core.phase import first_table_contact
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import full_targets, parse_primitive, quintic_part
from cloth_bench_ros.data import BagWriter, CLOUD_TOPIC, TrialInfo
from cloth_bench_ros.engines import engine_class, make_engine
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.safe_io import staged_directory
import numpy as np
import yaml

WALL_Y = -1.5  # m: a wall behind the scene, the background of the flying pixels


class SynthError(ClothBenchError, ValueError):
    """A synthetic reference that cannot be made (bad config/synth.yaml, diverged reference)."""


# Reference models (`cloth-bench synth --reference`): name -> file under config/. MuJoCo is the
# default.
REFERENCES = {'mujoco': 'synth.yaml', 'newton-vbd': 'synth_newton_vbd.yaml'}
DEFAULT_REFERENCE = 'mujoco'


def config_path(reference: str = DEFAULT_REFERENCE) -> Path:
    """Return config/synth.yaml (or another reference's file) of the source tree or package."""
    if reference not in REFERENCES:
        raise SynthError(
            f'unknown synthetic reference {reference!r} (valid: {", ".join(REFERENCES)})'
        )
    return share_dir('config') / REFERENCES[reference]


# ------------------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class Camera:
    """Pinhole depth camera at `position`, looking along -y with +z up (square pixels)."""

    width: int = scene.CAMERA_WIDTH_PX
    height: int = scene.CAMERA_HEIGHT_PX
    hfov_deg: float = scene.CAMERA_HFOV_DEG
    position: tuple[float, ...] = tuple(float(x) for x in scene.CAMERA_POSITION)

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        return (self.width / 2) / math.tan(math.radians(self.hfov_deg) / 2)

    @property
    def center(self) -> tuple[float, float]:
        """Principal point (u, v); pixel (u, v) has its centre at integer coordinates."""
        return (self.width - 1) / 2, (self.height - 1) / 2

    @property
    def rotation(self) -> np.ndarray:
        """World -> optical frame (x right, y down, z forward = world -y)."""
        return np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (..., 2) and depth (...) of world points (..., 3)."""
        cam = (np.asarray(points, float) - np.asarray(self.position)) @ self.rotation.T
        z = cam[..., 2]
        cu, cv = self.center
        with np.errstate(divide='ignore', invalid='ignore'):
            uv = np.stack(
                [cu + self.focal * cam[..., 0] / z, cv + self.focal * cam[..., 1] / z], axis=-1
            )
        return uv, z

    def back_project(self, u: np.ndarray, v: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """World points (n, 3) of pixels (u, v) at the given depths."""
        cu, cv = self.center
        cam = np.stack(
            [(u - cu) / self.focal * depth, (v - cv) / self.focal * depth, depth], axis=1
        )
        return cam @ self.rotation + np.asarray(self.position)


def rasterize(
    camera: Camera, triangles: np.ndarray, near: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """
    Z-buffer of world triangles (m, 3, 3): depth (H, W), inf where empty, and triangle id (-1).

    No face culling (both faces of the cloth render); depth is interpolated perspective-correctly
    (1/z is linear in the image); triangles reaching behind `near` are skipped.
    """
    H, W = camera.height, camera.width
    depth = np.full(H * W, np.inf)
    ids = np.full(H * W, -1, dtype=np.int64)
    uv, z = camera.project(triangles)
    a, b, c = uv[:, 0], uv[:, 1], uv[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    ok = (z > near).all(axis=1) & np.isfinite(area) & (np.abs(area) > 1e-12)
    uv = np.where(ok[:, None, None], uv, 0.0)
    lo = np.clip(np.ceil(uv.min(axis=1)), 0, [W, H]).astype(np.int64)
    hi = np.clip(np.floor(uv.max(axis=1)), -1, [W - 1, H - 1]).astype(np.int64)
    size = np.where(ok[:, None], np.maximum(hi - lo + 1, 0), 0)
    counts = size[:, 0] * size[:, 1]
    total = int(counts.sum())
    if total == 0:
        return depth.reshape(H, W), ids.reshape(H, W)
    tri = np.repeat(np.arange(len(triangles)), counts)
    local = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    pu = lo[tri, 0] + local % size[tri, 0]
    pv = lo[tri, 1] + local // size[tri, 0]
    pa, pb, pc = a[tri], b[tri], c[tri]
    inv_area = 1.0 / area[tri]
    w0 = ((pb[:, 0] - pu) * (pc[:, 1] - pv) - (pb[:, 1] - pv) * (pc[:, 0] - pu)) * inv_area
    w1 = ((pc[:, 0] - pu) * (pa[:, 1] - pv) - (pc[:, 1] - pv) * (pa[:, 0] - pu)) * inv_area
    w2 = 1.0 - w0 - w1
    eps = -1e-9
    inside = (w0 >= eps) & (w1 >= eps) & (w2 >= eps)
    zt = z[tri[inside]]
    d = 1.0 / (w0[inside] / zt[:, 0] + w1[inside] / zt[:, 1] + w2[inside] / zt[:, 2])
    pix = pv[inside] * W + pu[inside]
    order = np.lexsort((d, pix))
    first = np.ones(len(order), dtype=bool)
    first[1:] = pix[order][1:] != pix[order][:-1]
    keep = order[first]
    depth[pix[keep]] = d[keep]
    ids[pix[keep]] = tri[inside][keep]
    return depth.reshape(H, W), ids.reshape(H, W)


def mesh_triangles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Triangles (m, 3, 3) of a mesh."""
    return np.asarray(vertices, float)[np.asarray(faces)]


def _quad(p0, p1, p2, p3) -> np.ndarray:
    p = np.array([p0, p1, p2, p3], dtype=float)
    return np.stack([p[[0, 1, 2]], p[[0, 2, 3]]])


def background_triangles() -> np.ndarray:
    """Return the static scene behind the cloth: table top, table front face, a wall at WALL_Y."""
    (x0, x1), (y0, y1), zt = scene.TABLE_X, scene.TABLE_Y, scene.TABLE_TOP_Z
    zb = zt - scene.TABLE_THICKNESS
    top = _quad((x0, y0, zt), (x1, y0, zt), (x1, y1, zt), (x0, y1, zt))
    front = _quad((x0, y1, zb), (x1, y1, zb), (x1, y1, zt), (x0, y1, zt))
    wall = _quad((-5, WALL_Y, -5), (5, WALL_Y, -5), (5, WALL_Y, 5), (-5, WALL_Y, 5))
    return np.concatenate([top, front, wall])


# ------------------------------------------------------------------------------------- sensor


@dataclass(frozen=True)
class DepthNoise:
    """
    Azure-Kinect-like depth error: sigma(z) = sigma0 + sigma2 z^2 along the ray, flying pixels.

    Depth is reported in steps of `depth_step` (the Azure Kinect's depth image is in whole mm).

    A silhouette pixel of the cloth (a 4-neighbour deeper by more than `edge_jump`) becomes a
    flying pixel with probability `flying_fraction`: its depth is mixed uniformly between the
    cloth and the background behind it, as a time-of-flight pixel straddling the edge is.
    """

    sigma0: float = 0.001  # m
    sigma2: float = 0.0005  # m / m^2 (2.6 mm at 1.8 m)
    flying_fraction: float = 0.3
    edge_jump: float = 0.05  # m
    depth_step: float = 0.001  # m

    def sigma(self, depth: np.ndarray) -> np.ndarray:
        return self.sigma0 + self.sigma2 * np.asarray(depth) ** 2


@dataclass(frozen=True)
class Sensor:
    """Camera, noise and the clean-up of the real data: crop, outlier removal, point budget."""

    camera: Camera = Camera()
    noise: DepthNoise = DepthNoise()
    crop_min: tuple[float, float, float] = (
        scene.TABLE_X[0],
        scene.TABLE_Y[0],
        scene.TABLE_TOP_Z + 0.001,
    )
    crop_max: tuple[float, float, float] = (scene.TABLE_X[1], scene.TABLE_Y[1], 1.5)
    sor_neighbors: int = 20
    sor_std_ratio: float = 2.0
    max_points: int = 2000  # per frame, after outlier removal (keeps 6 bags within 25 MB)
    resolution: float = 2.0**-13  # m: points snap to this grid (0.12 mm), so zstd halves the bag

    @property
    def cleaning(self) -> cleaning.CleaningConfig:
        """Return the crop (above the table) and outlier removal of the one cleaning pipeline."""
        return cleaning.CleaningConfig(
            self.crop_min,
            self.crop_max,
            table_plane=False,
            sor_neighbors=self.sor_neighbors,
            sor_std_ratio=self.sor_std_ratio,
        )


def noisy_depth(
    depth: np.ndarray, cloth: np.ndarray, noise: DepthNoise, rng: np.random.Generator
) -> np.ndarray:
    """Depth image with ray noise on every pixel and flying pixels on the cloth's silhouette."""
    out = depth + rng.normal(0.0, 1.0, depth.shape) * noise.sigma(
        np.where(np.isfinite(depth), depth, 0.0)
    )
    if noise.flying_fraction > 0:
        _fly(out, depth, cloth, noise, rng)
    return np.round(out / noise.depth_step) * noise.depth_step if noise.depth_step > 0 else out


def _fly(
    out: np.ndarray,
    depth: np.ndarray,
    cloth: np.ndarray,
    noise: DepthNoise,
    rng: np.random.Generator,
) -> None:
    """Turn some silhouette pixels of the cloth into flying pixels, in place."""
    padded = np.pad(depth, 1, constant_values=np.inf)
    behind = np.max(
        [padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]], axis=0
    )  # the deepest 4-neighbour
    front = np.where(cloth, depth, 0.0)
    behind = np.where(np.isfinite(behind), behind, front + 1.0)  # no return: 1 m behind
    edge = cloth & (behind - front > noise.edge_jump)
    fly = edge & (rng.random(depth.shape) < noise.flying_fraction)
    mix = rng.random(int(fly.sum()))
    out[fly] = front[fly] + mix * (behind[fly] - front[fly])


def observe(
    sensor: Sensor,
    triangles: np.ndarray,
    rng: np.random.Generator,
    background: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """
    Return the point cloud (n, 3) the sensor makes of the cloth in front of `background`.

    `background` is a (depth, ids) z-buffer of the static scene from `rasterize` (none: empty).
    """
    cam = sensor.camera
    depth, _ = rasterize(cam, triangles)
    if background is not None:
        cloth = np.isfinite(depth) & (depth <= background[0])
        depth = np.minimum(depth, background[0])
    else:
        cloth = np.isfinite(depth)
    measured = noisy_depth(depth, cloth, sensor.noise, rng)
    v, u = np.nonzero(cloth)  # segmentation: the cloth's pixels, flying ones included
    points = cam.back_project(u.astype(float), v.astype(float), measured[v, u])
    points = cleaning.clean(points, sensor.cleaning)
    if len(points) > sensor.max_points:
        points = points[np.sort(rng.choice(len(points), sensor.max_points, replace=False))]
    return (
        np.round(points / sensor.resolution) * sensor.resolution
        if sensor.resolution > 0
        else points
    )


# ---------------------------------------------------------------------------- reference model


@dataclass(frozen=True)
class SynthConfig:
    """One synthetic trial: reference model (engine, grid, rate, parameters), sensor and seed."""

    cloth: str
    primitive: str
    engine: str
    grid: tuple[int, int]  # nx, nz of the reference cloth
    rate_hz: float  # a multiple of 30 fps: every frame falls on an engine step
    params: Mapping[str, Any]  # engine parameters
    seed: int = 0
    sensor: Sensor = Sensor()
    duration: float | None = None  # s of the quintic part to render; None: all of it
    provenance: str = ''

    @property
    def fps(self) -> float:
        return scene.REAL_FPS

    @property
    def frame_count(self) -> int:
        """Frames k = 0, 1, ... at t = k / fps while t <= duration - 1 / fps (132 and 420)."""
        duration = (
            quintic_part(self.primitive).duration if self.duration is None else self.duration
        )
        return int(math.floor(duration * self.fps + 1e-9))

    @property
    def steps_per_frame(self) -> int:
        n = self.rate_hz / self.fps
        if abs(n - round(n)) > 1e-9 or round(n) < 1:
            raise SynthError(
                f'synthetic reference rate {self.rate_hz:g} Hz is not a multiple of'
                f' {self.fps:g} fps'
            )
        return int(round(n))

    def describe(self) -> str:
        """One line naming the reference model and the camera (the bag's `source`)."""
        p = dict(self.params)
        cam, noise = self.sensor.camera, self.sensor.noise
        physics = ', '.join(
            f'{k} {p[k]:g}'
            for k in (
                'mass',
                'young',
                'poisson',
                'thickness',
                'bending',
                'tri_stiffness',
                'friction',
            )
            if k in p
        )
        integrator = f'integrator {p["integrator"]}, ' if 'integrator' in p else ''
        return (
            f'synthetic: reference {self.engine} {p.get("model", "")} cloth'
            f' {self.grid[0]}x{self.grid[1]}, {integrator}{self.rate_hz:g} Hz, self-collision'
            f' {"on" if p.get("self_collision") else "off"} ({physics}), seed {self.seed}; virtual'
            f' Azure Kinect {cam.width}x{cam.height} hfov {cam.hfov_deg:g} deg at'
            f' ({", ".join(f"{x:g}" for x in cam.position)}) looking along -y, z-buffer'
            f' visibility, depth noise {1000 * noise.sigma0:g} mm + {1000 * noise.sigma2:g} mm/m^2'
            f' z^2 in {1000 * noise.depth_step:g} mm steps, flying pixels'
            f' {noise.flying_fraction:g} of the silhouette, crop z > {self.sensor.crop_min[2]:g}'
            f' m, SOR {self.sensor.sor_neighbors}/{self.sensor.sor_std_ratio:g}, at most'
            f' {self.sensor.max_points} points'
        )


def reference_config(
    cloth: str,
    primitive: str,
    seed: int = 0,
    path: Path | None = None,
    reference: str = DEFAULT_REFERENCE,
    **overrides: Any,
) -> SynthConfig:
    """
    Return the reference model of `cloth` and `primitive` from the reference's config file.

    The file is config/synth.yaml for MuJoCo; SynthError if unknown. `overrides` replace
    SynthConfig fields (e.g. a coarser grid or a shorter duration for tests).
    """
    primitive = parse_primitive(primitive).value
    path = path or config_path(reference)
    try:
        doc = yaml.safe_load(path.read_text(encoding='utf-8'))
        ref = doc['reference']
        cloths = doc['cloths']
    except (OSError, yaml.YAMLError, KeyError, TypeError) as exc:
        raise SynthError(f'synthetic reference config {path} is unreadable ({exc})') from None
    if cloth not in cloths:
        raise SynthError(f'unknown cloth {cloth!r} in {path} (valid: {", ".join(cloths)})')
    entry = cloths[cloth]
    if primitive not in entry:
        raise SynthError(f'{path}: cloth {cloth} has no {primitive} entry')
    params = {**ref.get('params', {}), **entry[primitive]}
    engine_class(ref['engine']).validate_params(
        params
    )  # EngineError (a ValueError) names the bad one
    config = SynthConfig(
        cloth=cloth,
        primitive=primitive,
        seed=int(seed),
        engine=str(ref['engine']),
        grid=(int(ref['grid'][0]), int(ref['grid'][1])),
        rate_hz=float(ref['rate_hz']),
        params=params,
        provenance=str(entry.get('provenance', '')).strip(),
    )
    return replace(config, **overrides)


def simulate_reference(config: SynthConfig) -> Iterator[tuple[int, np.ndarray]]:
    """(frame k, vertices (n, 3)) of the reference model at t = k / fps of the quintic part."""
    per_frame = config.steps_per_frame
    targets = full_targets(config.primitive, config.rate_hz)
    start = targets.quintic_index
    last = start + (config.frame_count - 1) * per_frame
    engine = make_engine(
        config.engine, config.rate_hz, dict(config.params), ClothGrid(*config.grid)
    )
    try:
        vertices = engine.reset(config.seed, targets.left[0], targets.right[0])
        for i in range(1, last + 1):
            vertices = engine.step(targets.left[i], targets.right[i])
            if i >= start and (i - start) % per_frame == 0:
                if engine.diverged:
                    raise SynthError(
                        f'synthetic reference {config.cloth} {config.primitive} diverged at step'
                        f' {i}: {engine.divergence.reason if engine.divergence else ""}'
                    )
                yield (i - start) // per_frame, vertices
    finally:
        engine.close()


def coarse_vertices(
    vertices: np.ndarray, fine: tuple[int, int], coarse: tuple[int, int]
) -> np.ndarray:
    """Return the vertices of a coarse grid nested in a fine one (every n-th row and column)."""
    (fx, fz), (cx, cz) = fine, coarse
    if (fx - 1) % (cx - 1) or (fz - 1) % (cz - 1):
        raise ValueError(f'grid {cx}x{cz} is not nested in grid {fx}x{fz}')
    grid = np.asarray(vertices).reshape(fz, fx, 3)
    return grid[:: (fz - 1) // (cz - 1), :: (fx - 1) // (cx - 1)].reshape(-1, 3)


def frame_stamp_ns(k: int, fps: float = scene.REAL_FPS) -> int:
    """Stamp of frame k, from the start of the quintic part."""
    return round(k * 1_000_000_000 / fps)


def synthetic_frames(config: SynthConfig) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """(frame k, reference vertices (n, 3), points (m, 3)) of every synthetic frame."""
    faces = ClothGrid(*config.grid).faces()
    sensor = config.sensor
    background = rasterize(sensor.camera, background_triangles())
    rng = np.random.default_rng([config.seed, 0x5EED])
    for k, vertices in simulate_reference(config):
        yield k, vertices, observe(sensor, mesh_triangles(vertices, faces), rng, background)


def render_frames(config: SynthConfig) -> Iterator[tuple[int, np.ndarray]]:
    """Return (stamp_ns, points (n, 3)) of every synthetic frame, from the quintic part's start."""
    for k, _, points in synthetic_frames(config):
        yield frame_stamp_ns(k, config.fps), points


def trial_info(config: SynthConfig, clouds: list[np.ndarray] | None = None) -> TrialInfo:
    """
    Return trial 0 of the cloth.

    A dynamic trial's change of phase is the first table contact in its clouds.

    None if the clouds never touch the table (a shortened trial): its runs then say so and
    score every frame.
    """
    cop = None
    if config.primitive == 'dynamic':
        cop = first_table_contact(clouds or []).index  # frame k is stamped k / fps from the start
    return TrialInfo(config.cloth, 0, config.primitive, cop, config.describe(), fps=config.fps)


def write_synthetic_bag(
    config: SynthConfig,
    out_dir: Path,
    overwrite: bool = False,
    progress: bool = False,
    on_frame: Callable[[int, np.ndarray, np.ndarray], None] | None = None,
) -> Path:
    """
    Render `config` into a rosbag2 MCAP bag at out_dir (clouds on CLOUD_TOPIC); the bag path.

    `on_frame(k, reference_vertices, points)` sees every frame as it is written. The bag is
    written beside out_dir and renamed when complete: a failed run leaves no bag (and an old one
    intact), never one that reads as complete without its clouds.
    """
    out_dir = Path(out_dir)
    with staged_directory(out_dir, overwrite) as staged:  # output checks fail before simulating
        frames = synthetic_frames(config)
        if progress:
            from tqdm import tqdm

            frames = tqdm(frames, total=config.frame_count, unit='frame', desc=out_dir.name)
        rendered = list(
            frames
        )  # the trial (its change of phase) is written first, found from the clouds
        with BagWriter(
            staged, trial_info(config, [points for _, _, points in rendered])
        ) as writer:
            for k, vertices, points in rendered:
                writer.write_cloud(CLOUD_TOPIC, frame_stamp_ns(k, config.fps), points)
                if on_frame is not None:
                    on_frame(k, vertices, points)
            if writer.counts.get(CLOUD_TOPIC, 0) != config.frame_count:
                raise SynthError(
                    f'synthetic bag {out_dir}: {writer.counts.get(CLOUD_TOPIC, 0)} of '
                    f'{config.frame_count} frames rendered'
                )
    return out_dir


def synth_command(
    cloth: str,
    primitive: str,
    out: Path,
    seed: int = 0,
    overwrite: bool = False,
    progress: bool = True,
    reference: str = DEFAULT_REFERENCE,
    rate_hz: float | None = None,
) -> Path:
    """`cloth-bench synth`: the synthetic bag of a cloth and primitive from a reference."""
    config = reference_config(cloth, primitive, seed, reference=reference)
    if rate_hz is not None:
        config = replace(config, rate_hz=float(rate_hz))
        config.steps_per_frame  # SynthError before anything is simulated
    return write_synthetic_bag(config, Path(out), overwrite, progress)
