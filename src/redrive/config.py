"""Run configuration (L4): frozen dataclasses loaded from TOML."""
