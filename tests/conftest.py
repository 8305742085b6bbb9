"""Shared fixtures: the real PTL photos from ../shared (skipped cleanly where absent), and a
frames folder as `crossing-data frames` writes it."""

import os
from pathlib import Path

import numpy as np
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


@pytest.fixture
def make_frames_dir(tmp_path):
    """``make(frames)``: ``tmp_path/frames`` with a black 4x4 image at each relative path and the
    ``frames.csv`` that `crossing-data frames` writes (the source is the first folder)."""
    from crossing_assist.data_tools.images import save_rgb  # noqa: PLC0415

    def make(frames: list[str]) -> Path:
        d = tmp_path / "frames"
        for f in frames:
            save_rgb(d / f, np.zeros((4, 4, 3), np.uint8))
        (d / "frames.csv").write_text("image,source,video,t_s\n" + "".join(
            f"{f},vid:{f.split('/')[0]},x.mp4,0\n" for f in frames))
        return d
    return make
