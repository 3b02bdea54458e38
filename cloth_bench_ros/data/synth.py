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

from cloth_bench_ros.core import scene
from cloth_bench_ros.core.phase import first_table_contact
from cloth_bench_ros.core.scene import ClothGrid
from cloth_bench_ros.core.trajectory import as_task, full_targets, parse_primitive
from cloth_bench_ros.data import BagWriter, CLOUD_TOPIC, TrialInfo
from cloth_bench_ros.data.virtual_camera import (
    background_triangles, mesh_triangles, observe, rasterize, Sensor
)
from cloth_bench_ros.engines import engine_class, make_engine
from cloth_bench_ros.errors import ClothBenchError
from cloth_bench_ros.paths import share_dir
from cloth_bench_ros.safe_io import staged_directory
import numpy as np
from tqdm import tqdm
import yaml


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
            as_task(self.primitive).duration if self.duration is None else self.duration
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
    grid = ClothGrid(*config.grid)  # a reference's parameters are set for its own grid
    engine = make_engine(config.engine, config.rate_hz, dict(config.params), grid, grid)
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
        raise SynthError(f'grid {cx}x{cz} is not nested in grid {fx}x{fz}')
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
    device: str | None = None,
) -> Path:
    """`cloth-bench synth`: the synthetic bag of a cloth and primitive from a reference."""
    config = reference_config(cloth, primitive, seed, reference=reference)
    if device is not None:  # the Newton reference's compute device
        if config.engine != 'newton':
            raise SynthError(f'--device: the {reference} reference runs on {config.engine}')
        config = replace(config, params={**config.params, 'device': device})
    if rate_hz is not None:
        config = replace(config, rate_hz=float(rate_hz))
        config.steps_per_frame  # SynthError before anything is simulated
    return write_synthetic_bag(config, Path(out), overwrite, progress)
