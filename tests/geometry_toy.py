"""A schema-2 toy bundle (the bright-strip toy of runtime_toy.py with a ``geometry`` block):
``fit: stretch`` (the toy graph resizes whatever comes), distinct default FOVs per orientation
so a test can tell which one a heading used."""

from __future__ import annotations

from pathlib import Path

from runtime_toy import toy_graph_bytes, toy_meta

from crossing_assist.bundle import write_bundle

LANDSCAPE_FOV, PORTRAIT_FOV = 80.0, 50.0


def toy2_meta(landscape: float = LANDSCAPE_FOV, portrait: float = PORTRAIT_FOV, **geometry) -> dict:
    meta = toy_meta()
    meta["schema_version"] = 2
    meta["fov_deg"] = landscape
    meta["geometry"] = {"fit": "stretch", "strips": "frame",
                        "camera_fov_deg": {"landscape": landscape, "portrait": portrait},
                        "train_fov_deg": 67.0, **geometry}
    return meta


def make_toy2_bundle(folder: str | Path, **kw) -> Path:
    meta = toy2_meta(**kw)
    return write_bundle(folder, toy_graph_bytes(meta), meta)
