"""
A virtual Azure Kinect: rasterise a cloth mesh into a z-buffer and return the cloud it would see.

Pinhole camera placed as docs/benchmark.md section 1 says (only the surfaces it sees survive),
Azure-Kinect-like depth noise and flying pixels at the silhouette, back-projection to the world
frame, the crop to the cloth above the table, the project's cleaning pipeline and a point budget.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

from cloth_bench_ros.core import cleaning, scene
import numpy as np

WALL_Y = -1.5  # m: a wall behind the scene, the background of the flying pixels


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
