"""The lane agents' line interpolation gives shapely's (GEOS's) doubles, bit for bit."""

from __future__ import annotations

import numpy as np
import shapely

from redrive.closedloop.lane_tracks import Track, _interpolated, on_line


def _track(xy: np.ndarray) -> Track:
    line = shapely.LineString(xy)
    one = np.zeros(1)
    return Track(
        object_id=1, stamps_ns=np.zeros(1, dtype=np.int64), xy=xy[:1], yaw_rad=one,
        length_m=4.0, width_m=2.0, line=line, s_log=one, stops=[], desired_speed_mps=10.0,
        lanes=(), line_length_m=float(line.length),
    )  # fmt: skip


def test_interpolating_the_line_matches_shapely_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for n in (2, 3, 17, 200):
        # a wandering lane line of awkward doubles (uneven segments, a short one)
        steps = rng.normal(size=(n - 1, 2)) * rng.uniform(0.01, 30.0, size=(n - 1, 1))
        xy = np.vstack(
            [[rng.uniform(-5e3, 5e3, 2)], rng.uniform(-5e3, 5e3, 2) + np.cumsum(steps, 0)]
        )
        track = _track(xy)
        length = track.line_length_m
        ends = np.cumsum(np.hypot(*np.diff(xy, axis=0).T))
        s = np.concatenate([
            np.linspace(0.0, length, 997), ends, np.nextafter(ends, 0.0), np.nextafter(ends, np.inf),
            [0.0, 5e-324, length, np.nextafter(length, 0.0)],
        ])  # fmt: skip
        s = s[(s >= 0.0) & (s <= length)]
        want = shapely.get_coordinates(shapely.line_interpolate_point(track.line, s))
        got = np.array([_interpolated(track, float(v)) for v in s])
        np.testing.assert_array_equal(got, want)  # the same doubles, not merely close
        x, y, _yaw = on_line(track, length + 10.0)  # clamped to the line's end
        assert (x, y) == tuple(xy[-1])
