"""Runtime test helpers: the toy bundles (built by :mod:`crossing_assist.testing.toy_bundle`,
the one toy builder), bright-bar frames and clips, the shared ``toy_bundle`` fixture,
``needs_audio`` (skips a test without the system PortAudio), and a graph's outputs with its random
draws seeded (``seeded``, ``graph_outputs``: two graphs compared bit for bit).

The toy finds the brightest vertical strip: a bright bar on a dark frame -> that strip's bin with
high confidence; a frame with no bar (flat, or noise) -> near-uniform, high-entropy probabilities.
``TOY2`` is the schema-2 toy: ``fit: stretch`` (the toy graph resizes whatever comes) and distinct
default FOVs per orientation, so a test can tell which one a heading used.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from crossing_assist.geometry import Geometry
from crossing_assist.testing.toy_bundle import RUNTIME_TOY, make_toy_bundle, toy_meta, toy_model_bytes  # noqa: F401

def _sounddevice_ok() -> bool:
    try:
        import sounddevice  # noqa: F401
    except (ImportError, OSError):
        return False
    return True


#: Skips a test that plays through sounddevice where the system PortAudio (libportaudio2) is missing.
needs_audio = pytest.mark.skipif(not _sounddevice_ok(), reason="PortAudio (libportaudio2) is not installed")

LANDSCAPE_FOV, PORTRAIT_FOV = 80.0, 50.0
TOY2 = dataclasses.replace(RUNTIME_TOY, geometry=Geometry(fit="stretch", camera_fov_deg=(LANDSCAPE_FOV, PORTRAIT_FOV),
                                                          train_fov_deg=67.0))


def bar_frame(x: float | None, h: int = 72, w: int = 96, noise: float = 0.0,
              rng: np.random.Generator | None = None) -> np.ndarray:
    """A dark H x W x 3 uint8 frame with a bright vertical bar centred at fraction ``x`` of the
    width (``None`` = no bar); ``noise`` > 0 fills it with uniform noise of that amplitude."""
    img = np.full((h, w, 3), 20, dtype=np.uint8)
    if noise > 0:
        rng = rng or np.random.default_rng(0)
        img = rng.integers(0, int(255 * noise) + 1, size=(h, w, 3)).astype(np.uint8)
    if x is not None:
        half = max(1, w // 24)
        c = int(round(x * w))
        img[:, max(0, c - half):min(w, c + half)] = 240
    return img


def bar_dataset(root: str | Path, n: int = 6, unknown: bool = False, split: str = "val",
                source: str | None = None) -> Path:
    """A dataset folder of ``n`` bar frames (strips 1, 6, 11, 4, ...; ``unknown``: no bar, label
    ``unknown``) in ``split``, from ``source`` (None: two sources, ``src:0`` and ``src:1``)."""
    from crossing_assist.actions import UNKNOWN, bin_center_x
    from crossing_assist.data_tools.images import save_rgb
    from crossing_assist.data_tools.manifest import Row, write_manifest

    root = Path(root)
    rows = []
    for i in range(n):
        strip = 1 + (i * 5) % 12
        save_rgb(root / "images" / f"f{i}.png", bar_frame(None if unknown else bin_center_x(strip), h=72, w=96))
        rows.append(Row(f"images/f{i}.png", UNKNOWN if unknown else strip, None if unknown else bin_center_x(strip),
                        source or f"src:{i % 2}", split, {}, ()))
    write_manifest(root, rows)
    return root


def write_clip(path: str | Path, xs, fps: float = 30.0, h: int = 72, w: int = 96, noise: float = 0.0,
               seed: int = 0) -> Path:
    """An mp4 (mp4v) of bar frames at positions ``xs`` (None = no bar); returns the path."""
    import cv2

    rng = np.random.default_rng(seed)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    for x in xs:
        writer.write(cv2.cvtColor(bar_frame(x, h, w, noise=noise, rng=rng), cv2.COLOR_RGB2BGR))
    writer.release()
    return Path(path)


try:
    import pytest

    @pytest.fixture(scope="session")
    def toy_bundle(tmp_path_factory) -> Path:
        """A toy bundle folder shared by the runtime tests."""
        return make_toy_bundle(tmp_path_factory.mktemp("toy") / "bundle")
except ImportError:  # pragma: no cover
    pass


def seeded(model):
    """A copy of ``model`` whose random draws are seeded (one seed each, in graph order), so that
    onnxruntime draws alike in two graphs whose random nodes come in the same order."""
    import onnx

    m = onnx.ModelProto()
    m.CopyFrom(model)
    for i, node in enumerate(n for n in m.graph.node if n.op_type == "RandomUniformLike"):
        node.attribute.append(onnx.helper.make_attribute("seed", float(i + 1)))
    return m


def graph_outputs(model, frames):
    """The outputs of ``model`` (an ``onnx.ModelProto``) on ``frames`` stacked, in onnxruntime."""
    import onnxruntime as ort

    return ort.InferenceSession(model.SerializeToString()).run(None, {"frames": np.stack(frames)})
