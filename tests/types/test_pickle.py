"""Frames cross process boundaries (engine worker processes): they must pickle and stay frozen."""

from __future__ import annotations

import pickle

import numpy as np

from redrive.types import Frame, PointCloud, SensorData, SensorType


def test_frame_with_point_cloud_round_trips_through_pickle() -> None:
    cloud = PointCloud(
        xyz=np.arange(12, dtype=np.float32).reshape(4, 3),
        channels={"intensity": np.array([1, 2, 3, 4], dtype=np.uint8)},
    )
    lidar = SensorData(sensor_id="lidar", sensor_type=SensorType.LIDAR, stamp_ns=5, data=cloud)
    frame = Frame(stamp_ns=5, index=3, sensors={"lidar": lidar}, ground_truth=())

    back = pickle.loads(pickle.dumps(frame, protocol=pickle.HIGHEST_PROTOCOL))

    got = back.sensors["lidar"].data
    assert isinstance(got, PointCloud)
    np.testing.assert_array_equal(got.xyz, cloud.xyz)
    np.testing.assert_array_equal(got.channels["intensity"], [1, 2, 3, 4])
    assert not got.xyz.flags.writeable
    assert not got.channels["intensity"].flags.writeable
    assert back.index == 3
    assert back.ground_truth == ()
