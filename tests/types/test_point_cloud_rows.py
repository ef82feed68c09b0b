"""``PointCloud.many_from_rows``: the decoders' trusted path gives what the checked one gives."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from redrive.types import PointCloud


def _frozen(values: np.ndarray) -> np.ndarray:
    values.flags.writeable = False
    return values


def _rows(count: int, n: int) -> tuple[np.ndarray, list[tuple[str, np.ndarray]]]:
    rng = np.random.default_rng(count * 100 + n)
    xyz = _frozen(rng.normal(0, 10, (count, n, 3)).astype(np.float32))
    # Strided rows of one structured buffer, as a decoder views them.
    points = np.zeros((count, n), dtype=[("i", "<f4"), ("ring", "<u2"), ("t", "<f8")])
    points["i"] = rng.uniform(0, 1, (count, n))
    points["ring"] = rng.integers(0, 64, (count, n))
    points["t"] = rng.uniform(0, 0.1, (count, n))
    points.flags.writeable = False
    return xyz, [(name, points[name]) for name in ("i", "ring", "t")]


@pytest.mark.parametrize(("count", "n"), [(5, 40), (1, 1), (3, 0)])
def test_clouds_from_rows_equal_the_checked_constructor_s(count: int, n: int) -> None:
    xyz, channels = _rows(count, n)
    clouds = PointCloud.many_from_rows(xyz, channels)
    assert len(clouds) == count
    for i, cloud in enumerate(clouds):
        checked = PointCloud(xyz=xyz[i].copy(), channels={k: v[i].copy() for k, v in channels})
        assert type(cloud) is PointCloud
        assert cloud.xyz.dtype == np.float32
        assert cloud.xyz.shape == (n, 3)
        assert cloud.xyz.flags.c_contiguous
        assert not cloud.xyz.flags.writeable
        np.testing.assert_array_equal(cloud.xyz, checked.xyz)
        assert list(cloud.channels) == list(checked.channels) == ["i", "ring", "t"]
        for name, values in cloud.channels.items():
            assert values.dtype == checked.channels[name].dtype
            assert values.shape == (n,)
            assert not values.flags.writeable
            np.testing.assert_array_equal(values, checked.channels[name])
        with pytest.raises(TypeError):
            cloud.channels["i"] = checked.channels["i"]  # type: ignore[index]
        # Pickled (to a worker process) it is rebuilt through the checked constructor.
        back = pickle.loads(pickle.dumps(cloud))
        np.testing.assert_array_equal(back.xyz, cloud.xyz)
        assert not back.channels["t"].flags.writeable


def test_clouds_from_rows_without_channels() -> None:
    xyz, _ = _rows(4, 7)
    clouds = PointCloud.many_from_rows(xyz, [])
    assert [len(c) for c in clouds] == [7] * 4
    assert all(dict(c.channels) == {} for c in clouds)


def test_clouds_from_rows_refuse_what_the_checks_would_refuse() -> None:
    xyz, channels = _rows(3, 5)
    writable = xyz.copy()
    with pytest.raises(ValueError, match="read-only float32"):
        PointCloud.many_from_rows(writable, channels)
    with pytest.raises(ValueError, match="read-only float32"):
        PointCloud.many_from_rows(_frozen(xyz.astype(np.float64)), channels)
    with pytest.raises(ValueError, match="read-only float32"):
        PointCloud.many_from_rows(_frozen(xyz.reshape(3, 15)), channels)
    short = [("i", channels[0][1][:, :4])]
    with pytest.raises(ValueError, match="channel 'i'"):
        PointCloud.many_from_rows(xyz, short)
    with pytest.raises(ValueError, match="channel 'i'"):
        PointCloud.many_from_rows(xyz, [("i", channels[0][1].copy())])  # writable
    structured = _frozen(np.zeros((3, 5), dtype=[("a", "<f4")]))
    with pytest.raises(ValueError, match="channel 's'"):
        PointCloud.many_from_rows(xyz, [("s", structured)])
    with pytest.raises(ValueError, match="channel 'i'"):
        PointCloud.many_from_rows(xyz, [channels[0], channels[0]])


@pytest.mark.parametrize("arity", [0, 1, 3, 32, 33, 40])
def test_many_from_frozen_maps_every_cloud_s_channels_in_order(arity: int) -> None:
    """Each cloud's channels are its own read-only mapping, the names in the given order, for
    the arities built with a dict display (up to 32) and the general path past them."""
    xyz, _ = _rows(3, 5)
    names = [f"c{k:02d}" for k in range(arity)]
    columns = [
        [_frozen(np.full(5, 10 * i + k, dtype=np.int32)) for i in range(3)] for k in range(arity)
    ]
    clouds = PointCloud.many_from_frozen(list(xyz), list(zip(names, columns, strict=True)))
    assert len(clouds) == 3
    for i, cloud in enumerate(clouds):
        assert list(cloud.channels) == names
        for k, name in enumerate(names):
            assert cloud.channels[name] is columns[k][i]
        with pytest.raises(TypeError):
            cloud.channels["new"] = columns[0][0] if arity else xyz[0]  # type: ignore[index]
    assert clouds[0].channels is not clouds[1].channels
    if arity >= 2:
        # One channel a cloud short: refused, not silently cut.
        short = list(zip(names, columns, strict=True))
        short[-1] = (names[-1], columns[-1][:2])
        with pytest.raises(ValueError, match="2 of a channel"):
            PointCloud.many_from_frozen(list(xyz), short)
