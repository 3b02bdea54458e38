"""The PointCloud2 codec behaves like sensor_msgs_py.point_cloud2 on rosbags' message classes."""

import sys

from cloth_bench_ros.core.pointcloud2 import (
    create_cloud_xyz32,
    create_cloud_xyz_fields,
    drop_nan,
    FLOAT32,
    FLOAT64,
    PointCloudError,
    read_field,
    read_xyz,
)
from cloth_bench_ros.data.messages import deserialize, serialize
from cloth_bench_ros.runtime.messages import Header, PointCloud2, PointField
import numpy as np
import pytest


def make(points):
    return create_cloud_xyz32(Header(frame_id='world'), points, PointCloud2, PointField)


def test_round_trip_xyz32_and_layout():
    pts = np.random.default_rng(0).normal(size=(100, 3))
    msg = make(pts)
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 100, 12, 1200)
    assert [f.name for f in msg.fields] == ['x', 'y', 'z'] and all(
        f.datatype == FLOAT32 for f in msg.fields
    )
    assert msg.is_dense and msg.is_bigendian == (sys.byteorder != 'little')
    assert np.array_equal(read_xyz(msg), pts.astype(np.float32).astype(np.float64))


def test_survives_cdr_serialisation():
    pts = np.random.default_rng(1).normal(size=(10, 3))
    msg = deserialize(
        serialize(make(pts), 'sensor_msgs/msg/PointCloud2'), 'sensor_msgs/msg/PointCloud2'
    )
    assert np.array_equal(read_xyz(msg), read_xyz(make(pts)))


def test_nan_points_make_the_cloud_not_dense_and_are_dropped_and_counted():
    pts = np.array([[0, 0, 0], [np.nan, 1, 1], [2, 2, 2]], dtype=float)
    msg = make(pts)
    assert not msg.is_dense
    kept, dropped = drop_nan(read_xyz(msg))
    assert dropped == 1 and np.array_equal(kept, [[0, 0, 0], [2, 2, 2]])


def _custom_cloud(points, dtype, offsets, point_step, bigendian, height=1, row_pad=0):
    n = len(points)
    width = n // height
    order = '>' if bigendian else '<'
    rec = np.zeros(
        n,
        dtype=np.dtype(
            {
                'names': ['x', 'y', 'z'],
                'formats': [order + dtype] * 3,
                'offsets': offsets,
                'itemsize': point_step,
            }
        ),
    )
    for i, c in enumerate('xyz'):
        rec[c] = points[:, i]
    rows = rec.tobytes()
    row_bytes = point_step * width
    data = b''.join(
        rows[r * row_bytes:(r + 1) * row_bytes] + b'\0' * row_pad for r in range(height)
    )
    datatype = FLOAT32 if dtype == 'f4' else FLOAT64
    fields = [
        PointField(name=c, offset=o, datatype=datatype, count=1) for c, o in zip('xyz', offsets)
    ]
    return PointCloud2(
        header=Header(),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=bigendian,
        point_step=point_step,
        row_step=row_bytes + row_pad,
        data=np.frombuffer(data, np.uint8),
        is_dense=True,
    )


@pytest.mark.parametrize('bigendian', [False, True])
@pytest.mark.parametrize('dtype', ['f4', 'f8'])
def test_reads_padded_big_endian_and_float64_organised_clouds(bigendian, dtype):
    pts = np.random.default_rng(2).normal(size=(12, 3))
    size = 4 if dtype == 'f4' else 8
    msg = _custom_cloud(
        pts, dtype, [0, size, 2 * size + 4], 3 * size + 8, bigendian, height=3, row_pad=5
    )
    assert np.allclose(read_xyz(msg), pts.astype(dtype), rtol=0, atol=0)


def test_cloud_without_xyz_is_refused_with_its_fields():
    msg = make(np.zeros((2, 3)))
    msg.fields = [f for f in msg.fields if f.name != 'z']
    with pytest.raises(PointCloudError, match='no z field'):
        read_xyz(msg)


def test_short_data_is_refused():
    msg = make(np.zeros((4, 3)))
    msg.width = 5
    with pytest.raises(PointCloudError, match='does not hold'):
        read_xyz(msg)


def test_empty_cloud():
    assert read_xyz(make(np.zeros((0, 3)))).shape == (0, 3)


def test_an_extra_field_round_trips_through_cdr_beside_xyz():
    rng = np.random.default_rng(1)
    pts, error = rng.normal(size=(48, 3)), rng.uniform(0, 0.1, size=48)
    msg = create_cloud_xyz_fields(
        Header(frame_id='world'), pts, {'error': error}, PointCloud2, PointField
    )
    assert [(f.name, f.offset, f.datatype) for f in msg.fields] == [
        ('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32), ('error', 12, FLOAT32)
    ]
    assert (msg.point_step, msg.row_step, msg.width) == (16, 16 * 48, 48)
    pc2 = 'sensor_msgs/msg/PointCloud2'
    back = deserialize(serialize(msg, pc2), pc2)
    np.testing.assert_array_equal(read_xyz(back), pts.astype(np.float32))
    np.testing.assert_array_equal(read_field(back, 'error'), error.astype(np.float32))
    with pytest.raises(PointCloudError, match='no intensity field'):
        read_field(back, 'intensity')
