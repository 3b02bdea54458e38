"""
sensor_msgs/PointCloud2 <-> numpy, as sensor_msgs_py.point_cloud2 does it.

Works on any message object with PointCloud2's fields (the real sensor_msgs class or the
rosbags one); the classes to build with are passed in, so this module stays free of ROS.
"""

from __future__ import annotations

import array
import sys
from typing import Any, Sequence

from cloth_bench_ros.errors import ClothBenchError
import numpy as np

# sensor_msgs/PointField datatypes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
XYZ32_LAYOUT = [('x', 0, FLOAT32, 1), ('y', 4, FLOAT32, 1), ('z', 8, FLOAT32, 1)]
_NUMPY_TYPES = {
    INT8: 'i1',
    UINT8: 'u1',
    INT16: 'i2',
    UINT16: 'u2',
    INT32: 'i4',
    UINT32: 'u4',
    FLOAT32: 'f4',
    FLOAT64: 'f8',
}


class PointCloudError(ClothBenchError, ValueError):
    """A PointCloud2 that cannot be decoded (missing fields, bad sizes)."""


def _cloud_data(cloud_type: type, raw: bytes) -> object:
    """PointCloud2.data in the form the class expects: rclpy's fast path is array.array('B')."""
    if hasattr(cloud_type, '_fields_and_field_types'):  # an rclpy message class
        return array.array('B', raw)
    return np.frombuffer(raw, dtype=np.uint8)


def create_cloud_xyz32(header: Any, points: np.ndarray, cloud_type: type, field_type: type) -> Any:
    """Return a PointCloud2 of x, y, z float32 (point_step 12), one row, native byte order."""
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float32).reshape(-1, 3))
    return _float32_cloud(header, 'xyz', pts, cloud_type, field_type)


def create_cloud_xyz_fields(
    header: Any,
    points: np.ndarray,
    extra: dict[str, np.ndarray],
    cloud_type: type,
    field_type: type,
) -> Any:
    """Return a PointCloud2 of float32 x, y, z and one float32 field per `extra` column."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    names = ['x', 'y', 'z', *extra]
    table = np.empty((len(pts), len(names)), dtype=np.float32)
    table[:, :3] = pts
    for i, values in enumerate(extra.values()):
        table[:, 3 + i] = np.asarray(values, dtype=np.float32).reshape(len(pts))
    return _float32_cloud(header, names, table, cloud_type, field_type)


def _float32_cloud(
    header: Any, names: Sequence[str], table: np.ndarray, cloud_type: type, field_type: type
) -> Any:
    """Return a one-row PointCloud2 of the float32 columns of `table`, named `names`."""
    step = 4 * len(names)
    fields = [
        field_type(name=name, offset=4 * i, datatype=FLOAT32, count=1)
        for i, name in enumerate(names)
    ]
    return cloud_type(
        header=header,
        height=1,
        width=len(table),
        fields=fields,
        is_bigendian=sys.byteorder != 'little',
        point_step=step,
        row_step=step * len(table),
        data=_cloud_data(cloud_type, table.tobytes()),
        is_dense=bool(np.isfinite(table).all()),
    )


def read_field(cloud: Any, name: str) -> np.ndarray:
    """Return one numeric field of every point as float64 (n,), e.g. the `error` of a cloud."""
    by_name = {f.name: f for f in cloud.fields}
    if name not in by_name:
        known = ', '.join(sorted(by_name)) or 'none'
        raise PointCloudError(f'PointCloud2 has no {name} field (fields: {known})')
    f = by_name[name]
    if f.datatype not in _NUMPY_TYPES:
        raise PointCloudError(f'PointCloud2 field {name} has unknown datatype {f.datatype}')
    n, point_step, row_step = int(cloud.width) * int(cloud.height), int(cloud.point_step), int(
        cloud.row_step
    )
    dtype = np.dtype(('>' if cloud.is_bigendian else '<') + _NUMPY_TYPES[f.datatype])
    raw = _as_bytes(cloud.data)
    if (
        f.offset + dtype.itemsize > point_step
        or row_step < point_step * int(cloud.width)
        or len(raw) < row_step * int(cloud.height)
    ):
        raise PointCloudError(f'PointCloud2 field {name} lies outside its data')
    if n == 0:
        return np.zeros(0)
    rows = np.asarray(raw)[: row_step * int(cloud.height)].reshape(int(cloud.height), row_step)
    packed = np.ascontiguousarray(rows[:, : point_step * int(cloud.width)]).reshape(n, point_step)
    return packed[:, f.offset:f.offset + dtype.itemsize].copy().view(dtype).ravel().astype(float)


def _as_bytes(data: Any) -> bytes | np.ndarray:
    if isinstance(data, np.ndarray):
        return data.view(np.uint8).ravel()
    if isinstance(data, (bytes, bytearray, memoryview)):
        return np.frombuffer(data, dtype=np.uint8)
    return np.asarray(data, dtype=np.uint8)  # array.array or list from rclpy


def read_xyz(cloud: Any) -> np.ndarray:
    """Return the x, y, z of every point as float64 (n, 3), NaN points kept (see `drop_nan`)."""
    fields, n = cloud.fields, int(cloud.width) * int(cloud.height)
    if (  # the layout create_cloud_xyz32 writes, checked first: one flat read, no per-field copies
        len(fields) == 3
        and int(cloud.point_step) == 12
        and int(cloud.row_step) == 12 * int(cloud.width)
        and [(f.name, f.offset, f.datatype, f.count) for f in fields] == XYZ32_LAYOUT
    ):
        raw = _as_bytes(cloud.data)
        if n and len(raw) >= 12 * n:
            order = '>' if cloud.is_bigendian else '<'
            return np.frombuffer(raw, dtype=order + 'f4', count=3 * n).reshape(n, 3).astype(float)
    names = [f.name for f in fields]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise PointCloudError(f'PointCloud2 has two fields named {", ".join(twice)}')
    by_name = {f.name: f for f in cloud.fields}
    missing = [c for c in 'xyz' if c not in by_name]
    if missing:
        known = ', '.join(sorted(by_name)) or 'none'
        raise PointCloudError(f'PointCloud2 has no {"/".join(missing)} field (fields: {known})')
    n = int(cloud.width) * int(cloud.height)
    if n == 0:
        return np.zeros((0, 3))
    order = '>' if cloud.is_bigendian else '<'
    point_step, row_step = int(cloud.point_step), int(cloud.row_step)
    raw = _as_bytes(cloud.data)
    if row_step < point_step * int(cloud.width) or len(raw) < row_step * int(cloud.height):
        raise PointCloudError(
            f'PointCloud2 data of {len(raw)} bytes does not hold {cloud.height} rows of '
            f'{cloud.width} points (point_step {point_step}, row_step {row_step})'
        )
    # Any other layout: drop the padding at the end of each row so that points are evenly spaced.
    rows = np.asarray(raw)[: row_step * int(cloud.height)].reshape(int(cloud.height), row_step)
    packed = np.ascontiguousarray(rows[:, : point_step * int(cloud.width)]).reshape(n, point_step)
    out = np.empty((n, 3))
    for i, c in enumerate('xyz'):
        f = by_name[c]
        if f.datatype not in _NUMPY_TYPES:
            raise PointCloudError(f'PointCloud2 field {c} has unknown datatype {f.datatype}')
        dtype = np.dtype(order + _NUMPY_TYPES[f.datatype])
        if f.offset + dtype.itemsize > point_step:
            raise PointCloudError(f'PointCloud2 field {c} lies outside point_step {point_step}')
        out[:, i] = packed[:, f.offset:f.offset + dtype.itemsize].copy().view(dtype).ravel()
    return out


def as_carried(points: np.ndarray) -> np.ndarray:
    """Return points as a PointCloud2 of float32 x, y, z carries them, read back as float64."""
    return np.asarray(points).astype(np.float32).reshape(-1, 3).astype(np.float64)


def drop_nan(points: np.ndarray) -> tuple[np.ndarray, int]:
    """Points whose three coordinates are finite, and how many were dropped."""
    keep = np.isfinite(points).all(axis=1)
    return points[keep], int(len(points) - keep.sum())
