"""Shared fixtures and paths for the test suite."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO


@pytest.fixture(scope="session")
def boruszyn_dir() -> Path:
    """The real Boruszyn kite photos; tests using it skip where ../shared/data is absent."""
    path = SHARED_DATA / "boruszyn_kap"
    if not (path / "images").is_dir():
        pytest.skip(f"real data not available: {path} is absent")
    return path
