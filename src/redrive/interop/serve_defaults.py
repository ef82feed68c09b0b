"""Where ``redrive serve`` listens by default (importable without foxglove-sdk)."""

from __future__ import annotations

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT"]

#: loopback: a served log is not on the network unless the user says so.
DEFAULT_HOST = "127.0.0.1"
#: Foxglove's default WebSocket port.
DEFAULT_PORT = 8765
