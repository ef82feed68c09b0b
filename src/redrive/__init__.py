"""redrive — re-drive autonomous-driving algorithms on recorded or live sensor data."""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
