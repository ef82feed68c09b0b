"""Shared fixtures: the real third-party data in ../shared/data (skipped cleanly when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_ROOT = Path(__file__).resolve().parents[1]


def _shared_data_dir() -> Path | None:
    env = os.environ.get("REDRIVE_SHARED_DATA")
    candidates = [Path(env)] if env else []
    candidates += [_ROOT.parent / "shared" / "data", _ROOT / ".." / "shared" / "data"]
    for cand in candidates:
        if (cand / "README.md").is_file():
            return cand.resolve()
    return None


SHARED_DATA = _shared_data_dir()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data``; the test is skipped when it is not there."""
    if SHARED_DATA is None:
        pytest.skip("../shared/data is not present")
    return SHARED_DATA
