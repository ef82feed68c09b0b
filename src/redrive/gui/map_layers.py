"""The run's road map on the planview — no Qt here: lane boundaries (painted lines and road edges
apart), centrelines, crosswalks, drivable areas, intersections, stop lines, and each traffic light
in the colour of the state its frame records.

:func:`map_lines` turns the map (map frame) into segment groups once per run;
:func:`map_layers` re-expresses the groups near the ego in its base_link per frame, as the
planview's layers (name, colour, segments: the loader makes each a
:class:`~redrive.gui.scene.LayerLines`; this module sits below the session and the scene).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.types import LightState, RoadMap, VehicleState

__all__ = ["LIGHT_COLORS", "MAP_PREFIX", "MapLayer", "MapLines", "map_layers", "map_lines"]

#: the names of the map's layers start with it (the planview counts no boxes in them)
MAP_PREFIX = "map: "

Float = npt.NDArray[np.float64]
RGB = tuple[int, int, int]

#: (group, colour) in the order they are drawn (later on top).
_GROUPS: tuple[tuple[str, RGB], ...] = (
    ("drivable areas", (95, 95, 110)),
    ("intersections", (200, 170, 40)),
    ("centrelines", (70, 120, 210)),
    ("lane lines", (200, 200, 200)),
    ("road edges", (255, 140, 30)),
    ("crosswalks", (235, 235, 235)),
    ("stop lines", (255, 255, 255)),
)
LIGHT_COLORS: Mapping[LightState, RGB] = {
    LightState.RED: (240, 40, 40),
    LightState.YELLOW: (250, 200, 20),
    LightState.GREEN: (40, 220, 70),
    LightState.UNKNOWN: (150, 150, 150),
}
_LIGHT_HALF_M = 1.0  # a light: a 2 m square with a cross


@dataclass(frozen=True, slots=True, kw_only=True)
class MapLayer:
    """One planview layer of the map: ``segments`` (2K, 3) endpoints in base_link."""

    name: str
    color: RGB
    segments: Float


@dataclass(frozen=True, slots=True, kw_only=True)
class MapLines:
    """A road map as segments (map frame): ``groups`` name → (2M, 2) endpoints; ``lights``
    light id → (x, y)."""

    groups: Mapping[str, Float]
    lights: Mapping[str, tuple[float, float]]


def _pairs(line: Float) -> Float:
    line = np.asarray(line, dtype=np.float64)
    out = np.empty((2 * (len(line) - 1), 2), dtype=np.float64)
    out[0::2], out[1::2] = line[:-1], line[1:]
    return out


def _ring(polygon: Float) -> Float:
    ring = np.asarray(polygon, dtype=np.float64)
    return _pairs(np.vstack([ring, ring[:1]]))


def _stack(pieces: list[Float]) -> Float:
    return np.vstack(pieces) if pieces else np.zeros((0, 2), dtype=np.float64)


def map_lines(road_map: RoadMap) -> MapLines:
    """The map's elements as segment groups (the module text)."""
    groups: dict[str, list[Float]] = {name: [] for name, _ in _GROUPS}
    for lane in road_map.lanes:
        left, right = lane.boundaries()
        for bound, kind in ((left, lane.left_boundary_type), (right, lane.right_boundary_type)):
            if kind == "virtual":
                continue
            groups["road edges" if kind == "road_edge" else "lane lines"].append(_pairs(bound))
        groups["centrelines"].append(_pairs(lane.centerline))
    groups["drivable areas"] += [_ring(a.polygon) for a in road_map.areas]
    groups["intersections"] += [_ring(i.polygon) for i in road_map.intersections]
    groups["crosswalks"] += [_ring(c.polygon) for c in road_map.crosswalks]
    groups["stop lines"] += [_pairs(s.line) for s in road_map.stop_lines]
    lights = {
        t.light_id: (float(t.position[0]), float(t.position[1])) for t in road_map.traffic_lights
    }
    return MapLines(groups={k: _stack(v) for k, v in groups.items()}, lights=lights)


def _to_base(ego: VehicleState, xy: Float) -> Float:
    x0, y0, h = float(ego.position[0]), float(ego.position[1]), float(ego.heading_rad)
    c, s = math.cos(h), math.sin(h)
    dx, dy = xy[:, 0] - x0, xy[:, 1] - y0
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)


def _near(segments: Float, ego: VehicleState, radius_m: float) -> Float:
    """(2K, 3) endpoints in ``ego``'s base_link (z 0) of the segments with an end within
    ``radius_m``."""
    if len(segments) == 0:
        return np.zeros((0, 3), dtype=np.float64)
    xy = _to_base(ego, segments)
    near = (np.hypot(xy[:, 0], xy[:, 1]) <= radius_m).reshape(-1, 2).any(axis=1)
    kept = xy.reshape(-1, 2, 2)[near].reshape(-1, 2)
    return np.column_stack([kept, np.zeros(len(kept))])


def _light_marks(x: float, y: float) -> Float:
    h = _LIGHT_HALF_M
    corners = np.array([[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h]])
    cross = np.array([[x - h, y - h], [x + h, y + h], [x - h, y + h], [x + h, y - h]])
    return np.vstack([_ring(corners), cross])


def map_layers(
    lines: MapLines,
    ego: VehicleState,
    *,
    lights: Mapping[str, LightState] | None = None,
    radius_m: float = 120.0,
) -> list[MapLayer]:
    """The planview layers of the map near ``ego`` (in its base_link), the lights coloured by
    ``lights`` (light id → state; a light without one is grey)."""
    out = [
        MapLayer(
            name=MAP_PREFIX + name, color=color, segments=_near(lines.groups[name], ego, radius_m)
        )
        for name, color in _GROUPS
        if len(lines.groups.get(name, ())) > 0
    ]
    by_state: dict[LightState, list[Float]] = {}
    for light_id, (x, y) in lines.lights.items():
        state = (lights or {}).get(light_id, LightState.UNKNOWN)
        by_state.setdefault(state, []).append(_light_marks(x, y))
    for state, marks in by_state.items():
        out.append(
            MapLayer(
                name=f"{MAP_PREFIX}traffic lights ({state.value})",
                color=LIGHT_COLORS[state],
                segments=_near(np.vstack(marks), ego, radius_m),
            )
        )
    return [layer for layer in out if len(layer.segments)]
