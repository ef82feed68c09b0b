"""A run's traffic lights as shapes: each light of the road map drawn at its position, coloured
by the state the frame records (``traffic_lights`` table), with its stop line in the same colour.

Topic ``/redrive/traffic_lights`` (the map's frame, ``map``): per light a lamp box 0.5 × 0.5 × 1.2 m whose
centre stands :data:`LAMP_HEIGHT_M` above the map position (a map position is planar), a label
``light ID: state`` over it, and its stop line (the map's :class:`~redrive.types.StopLine`) on
the ground.  Red, yellow and green are drawn as such; unknown — and a light the frame records no
state of — grey.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from redrive.interop.shapes import BoxShape, Color, LabelShape, LineShape, ShapeSet
from redrive.types import LightState, RoadMap

__all__ = ["LAMP_HEIGHT_M", "LIGHTS_TOPIC", "STATE_COLORS", "light_shapes"]

LIGHTS_TOPIC = "/redrive/traffic_lights"
#: height of a lamp's centre above the ground, metres (the synthetic signal heads hang at 5 m)
LAMP_HEIGHT_M = 5.0
STATE_COLORS: Mapping[LightState, Color] = {
    LightState.RED: (0.95, 0.10, 0.10, 0.95),
    LightState.YELLOW: (1.00, 0.80, 0.05, 0.95),
    LightState.GREEN: (0.10, 0.85, 0.25, 0.95),
    LightState.UNKNOWN: (0.55, 0.55, 0.55, 0.80),
}


def light_shapes(road_map: RoadMap, states: Mapping[str, LightState], *, stamp_ns: int) -> ShapeSet:
    """The map's lights at one frame, ``states`` being light id → what it shows then."""
    stop_lines = {s.stop_line_id: s for s in road_map.stop_lines}
    boxes: list[BoxShape] = []
    labels: list[LabelShape] = []
    lines: list[LineShape] = []
    for light in road_map.traffic_lights:
        state = states.get(light.light_id, LightState.UNKNOWN)
        color = STATE_COLORS[state]
        x, y = (float(v) for v in light.position)
        boxes.append(
            BoxShape(
                id=f"light/{light.light_id}",
                center=(x, y, LAMP_HEIGHT_M),
                size=(0.5, 0.5, 1.2),
                yaw_rad=0.0,
                color=color,
            )
        )
        labels.append(
            LabelShape(
                id=f"light/{light.light_id}/label",
                position=(x, y, LAMP_HEIGHT_M + 1.2),
                text=f"light {light.light_id}: {state.value}",
                color=color,
                size_m=0.6,
            )
        )
        stop = stop_lines.get(light.stop_line_id) if light.stop_line_id is not None else None
        if stop is not None:
            points: Sequence[tuple[float, float, float]] = tuple(
                (float(px), float(py), 0.05) for px, py in stop.line.tolist()
            )
            lines.append(
                LineShape(
                    id=f"light/{light.light_id}/stop_line",
                    points=tuple(points),
                    color=color,
                    width_m=0.5,
                )
            )
    return ShapeSet(
        stamp_ns=stamp_ns,
        frame_id=road_map.frame_id,
        boxes=tuple(boxes),
        lines=tuple(lines),
        labels=tuple(labels),
    )
