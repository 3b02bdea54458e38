"""The benchmark scene (docs/benchmark.md, section 1): cloth, grippers, table, gravity, camera."""

from __future__ import annotations

from dataclasses import dataclass

from cloth_bench_ros import validation
import numpy as np

CLOTH_WIDTH = 0.50  # m, the grasped edge (along x)
CLOTH_LENGTH = 0.70  # m, the hanging length (along -z)
GRAVITY = -9.81  # m/s^2 along z

# Where the cloth hangs at rest; a task's settle phase moves the grippers on to its grasp pose
# (config/tasks/*.yaml).
GRIPPER_START_LEFT = np.array([0.00, 0.00, 1.00])
GRIPPER_START_RIGHT = np.array([0.50, 0.00, 1.00])

TABLE_TOP_Z = 0.195  # m
TABLE_X = (-0.30, 0.80)  # m; the benchmark asks for at least [-0.1, 0.7]
TABLE_Y = (-0.90, 0.90)  # m; the benchmark asks for at least [-0.8, 0.8]
TABLE_THICKNESS = 0.05  # m
# m: a cloud's points this close to the table's plane are the table's (the cleaning removes them)
TABLE_PLANE_DISTANCE = 0.01

REAL_FPS = 30.0  # real point clouds per second

# Azure Kinect, about 1.8 m in front of the cloth (+y), looking along -y, about 0.7 m high.
CAMERA_POSITION = np.array([0.25, 1.80, 0.70])
CAMERA_WIDTH_PX = 1280
CAMERA_HEIGHT_PX = 720
CAMERA_HFOV_DEG = 90.0  # colour camera, 16:9 mode


@dataclass(frozen=True)
class ClothGrid:
    """
    A rectangular cloth mesh of nx x nz vertices hanging in the x-z plane at y = 0.

    Vertex (i, j) sits at x = i * width / (nx - 1), z = top_z - j * length / (nz - 1); index
    j * nx + i. The grasped corners are (0, 0) and (nx - 1, 0).
    """

    nx: int = 11
    nz: int = 15
    width: float = CLOTH_WIDTH
    length: float = CLOTH_LENGTH
    top_z: float = float(GRIPPER_START_LEFT[2])

    def __post_init__(self) -> None:
        validation.grid(self.nx, self.nz)  # bounded before any mesh is allocated

    def vertices(self) -> np.ndarray:
        """Rest positions, shape (nx * nz, 3), in metres."""
        xs = np.linspace(0.0, self.width, self.nx)
        zs = self.top_z - np.linspace(0.0, self.length, self.nz)
        gx, gz = np.meshgrid(xs, zs)
        return np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], axis=1)

    def faces(self) -> np.ndarray:
        """Triangles, shape (2 * (nx - 1) * (nz - 1), 3), vertex indices."""
        tris = []
        for j in range(self.nz - 1):
            for i in range(self.nx - 1):
                a = j * self.nx + i
                b, c, d = a + 1, a + self.nx, a + self.nx + 1
                tris.append((a, c, b))
                tris.append((b, c, d))
        return np.asarray(tris, dtype=np.int64)

    @property
    def left_corner(self) -> int:
        return 0

    @property
    def right_corner(self) -> int:
        return self.nx - 1

    @property
    def spacing(self) -> tuple[float, float]:
        return self.width / (self.nx - 1), self.length / (self.nz - 1)

    def grasp_weights(self) -> np.ndarray:
        """Per vertex, 0 at the left corner's column to 1 at the right's (its column's share)."""
        return np.tile(np.linspace(0.0, 1.0, self.nx), self.nz)
