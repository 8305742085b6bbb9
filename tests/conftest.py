"""Shared fixtures: the real PTL photos from ../shared (skipped cleanly where absent)."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def ptl_root() -> Path | None:
    """The shared PTL folder: $CROSSING_PTL_DIR, else ../shared/data/ptl beside the repository."""
    env = os.environ.get("CROSSING_PTL_DIR")
    path = Path(env) if env else REPO.parent / "shared" / "data" / "ptl"
    return path if (path / "labels.csv").is_file() else None


@pytest.fixture(scope="session")
def ptl_dir() -> Path:
    path = ptl_root()
    if path is None:
        pytest.skip("the shared PTL data (../shared/data/ptl) is not here")
    return path
