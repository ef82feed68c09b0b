"""Traffic-light states → :class:`~redrive.types.TrafficData` (kind TRAFFIC_LIGHTS).

* ``redrive_msgs/msg/TrafficLightStateArray`` (what ``redrive synth`` writes on
  ``/ground_truth/traffic_lights``): ``ids[i]`` → ``TrafficLight.id``, ``states[i]`` → its
  :class:`~redrive.types.LightState` by the message's constants (UNKNOWN 0, RED 1, YELLOW 2,
  GREEN 3).  Arrays of different lengths, an unknown code or an id given twice are damage: an
  :class:`~redrive.errors.UnsupportedMessageError` that names the topic and the message.
"""

from __future__ import annotations

from typing import Any

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import header_stamp_ns, unsupported
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.io.ros.encode import LIGHT_STATE_CODES
from redrive.types import SensorType, TrafficData, TrafficLight

__all__ = ["TrafficLightStateArrayDecoder"]

_STATES = {code: state for state, code in LIGHT_STATE_CODES.items()}


class TrafficLightStateArrayDecoder:
    """``redrive_msgs/msg/TrafficLightStateArray`` → TrafficData (its lights)."""

    name = "traffic_light_states"
    msgtypes: tuple[str, ...] = ("redrive_msgs/msg/TrafficLightStateArray",)
    kind = DecodedKind.TRAFFIC_LIGHTS
    sensor_type: SensorType | None = None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        ids = [str(i) for i in msg.ids]
        codes = [int(c) for c in msg.states]
        if len(ids) != len(codes):
            raise unsupported(
                message,
                f"a TrafficLightStateArray with {len(ids)} ids but {len(codes)} states",
                "ids and states are parallel arrays; the message is damaged",
            )
        bad = sorted({c for c in codes if c not in _STATES})
        if bad:
            raise unsupported(
                message,
                f"a TrafficLightStateArray with state code(s) {bad}",
                "states are 0 (unknown), 1 (red), 2 (yellow) or 3 (green)",
            )
        if len(set(ids)) != len(ids):
            twice = sorted({i for i in ids if ids.count(i) > 1})
            raise unsupported(
                message,
                f"a TrafficLightStateArray naming light(s) {', '.join(map(repr, twice))} twice",
                "each light appears once per message",
            )
        lights = tuple(
            TrafficLight(id=i, state=_STATES[c]) for i, c in zip(ids, codes, strict=True)
        )
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=TrafficData(traffic_lights=lights),
        )
