"""A toy bundle for the runtime tests, built without torch (onnx.helper + crossing_assist.bundle).

The toy "policy" finds the brightest vertical strip: the graph resizes the uint8 RGB frame to
24 x 48, averages each of the 12 strips, and gives bin ``k`` the logit
``gain * (strip_k - mean) / 255``; ``unknown`` gets logit 0. A bright bar on a dark frame ->
that strip's bin with high confidence; a frame with no bar (flat, or noise) -> near-uniform,
high-entropy probabilities. MC dropout is real: ``RandomUniformLike >= p`` masks on the T
expanded logit copies, so the samples vary (as in the exported models).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from crossing_assist.actions import get_space
from crossing_assist.bundle import embedded_meta, write_bundle

T_SAMPLES = 8
DROP_P = 0.05
GAIN = 40.0
THRESHOLD = 1.0  # entropy (nats) where the gate's coefficient is one half


def _const(name: str, value, dtype=np.float32) -> onnx.TensorProto:
    return numpy_helper.from_array(np.asarray(value, dtype=dtype), name)


def toy_meta(threshold: float = THRESHOLD) -> dict:
    """The toy's bundle.json dict (13 actions, FOV 90, entropy threshold ``threshold``)."""
    space = get_space(13)
    return {
        "schema_version": 1,
        "model_file": "model.onnx",
        "actions": {"n": 13, "names": list(space.names), "bins": [list(g) for g in space.groups]},
        "fov_deg": 90.0,
        "input": {"layout": "NHWC", "dtype": "uint8", "color": "RGB", "size": [24, 48],
                  "mean": [0.5, 0.5, 0.5], "std": [0.25, 0.25, 0.25]},
        "mc": {"samples": T_SAMPLES, "p": DROP_P},
        "calibration": {"temperature": 1.0,
                        "conformal": {"coverage": 0.9, "threshold": 0.05, "n_frames": 0},
                        "uncertainty": {"measure": "entropy", "threshold": threshold}},
        "precision": "fp32",
        "training": {"backbone": "toy-bright-strip", "head": "none", "data": "none", "counts": {}},
        "metrics": {},
        "package_version": "0.1.0",
        "provenance": {"command": "tests/runtime_toy.py", "created": "test"},
    }


def toy_graph_bytes(meta: dict) -> bytes:
    """The toy ONNX model (opset 18) with the contract's input and five outputs."""
    a = 13
    n = helper.make_node
    nodes = [
        n("Cast", ["frames"], ["xf"], to=TensorProto.FLOAT),
        n("Resize", ["xf", "", "", "size"], ["xr"], axes=[1, 2], mode="linear"),
        n("ReduceMean", ["xr", "ax13"], ["col"], keepdims=0),           # [N, 48]
        n("Reshape", ["col", "shape_strips"], ["col3"]),                  # [N, 12, 4]
        n("ReduceMean", ["col3", "ax2"], ["strip"], keepdims=0),         # [N, 12]
        n("ReduceMean", ["strip", "ax1"], ["avg"], keepdims=1),          # [N, 1]
        n("Sub", ["strip", "avg"], ["dev"]),
        n("Mul", ["dev", "gain"], ["lbins"]),
        n("Mul", ["avg", "zero"], ["lunk"]),                              # [N, 1] zeros
        n("Concat", ["lunk", "lbins"], ["logits"], axis=1),              # [N, 13]
        n("Unsqueeze", ["logits", "ax0"], ["l1"]),
        n("Expand", ["l1", "tshape"], ["lt"]),                            # [T, N, 13]
        n("RandomUniformLike", ["lt"], ["u"], dtype=TensorProto.FLOAT),
        n("GreaterOrEqual", ["u", "p"], ["keep"]),
        n("Cast", ["keep"], ["keepf"], to=TensorProto.FLOAT),
        n("Mul", ["lt", "keepf"], ["ld"]),
        n("Mul", ["ld", "scale"], ["ls"]),
        n("Softmax", ["ls"], ["ps"], axis=-1),
        n("ReduceMean", ["ps", "ax0"], ["probs"], keepdims=0),
        n("Add", ["probs", "tiny"], ["pe"]), n("Log", ["pe"], ["lp"]), n("Mul", ["probs", "lp"], ["plp"]),
        n("ReduceSum", ["plp", "axm1"], ["nent"], keepdims=0), n("Neg", ["nent"], ["entropy"]),
        n("Add", ["ps", "tiny"], ["pse"]), n("Log", ["pse"], ["lps"]), n("Mul", ["ps", "lps"], ["pslp"]),
        n("ReduceSum", ["pslp", "axm1"], ["nse"], keepdims=0),             # [T, N]
        n("ReduceMean", ["nse", "ax0"], ["nmse"], keepdims=0),
        n("Add", ["entropy", "nmse"], ["mi_raw"]), n("Max", ["mi_raw", "zero1"], ["mutual_info"]),
        n("Sub", ["ps", "probs"], ["dp"]), n("Mul", ["dp", "dp"], ["dp2"]),
        n("ReduceMean", ["dp2", "ax0"], ["variance"], keepdims=0),
        n("ArgMax", ["ps"], ["am"], axis=-1, keepdims=0),
        n("OneHot", ["am", "depth", "onoff"], ["oh"], axis=-1),
        n("ReduceMean", ["oh", "ax0"], ["votes"], keepdims=0),
    ]
    inits = [
        _const("size", [24, 48], np.int64), _const("ax13", [1, 3], np.int64),
        _const("shape_strips", [0, 12, 4], np.int64), _const("ax2", [2], np.int64),
        _const("ax1", [1], np.int64), _const("ax0", [0], np.int64), _const("axm1", [-1], np.int64),
        _const("gain", GAIN / 255.0), _const("zero", 0.0), _const("zero1", [0.0]),
        _const("tshape", [T_SAMPLES, 1, 1], np.int64), _const("p", DROP_P),
        _const("scale", 1.0 / (1.0 - DROP_P)), _const("tiny", 1e-12),
        _const("depth", [a], np.int64), _const("onoff", [0.0, 1.0]),
    ]
    f = TensorProto.FLOAT
    graph = helper.make_graph(
        nodes, "toy_bright_strip",
        [helper.make_tensor_value_info("frames", TensorProto.UINT8, ["N", "H", "W", 3])],
        [helper.make_tensor_value_info("probs", f, ["N", a]),
         helper.make_tensor_value_info("entropy", f, ["N"]),
         helper.make_tensor_value_info("mutual_info", f, ["N"]),
         helper.make_tensor_value_info("variance", f, ["N", a]),
         helper.make_tensor_value_info("votes", f, ["N", a])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)])
    model.ir_version = 8
    import json
    helper.set_model_props(model, {"bundle_json": json.dumps(embedded_meta(meta)), "schema_version": "1"})
    onnx.checker.check_model(model)
    return model.SerializeToString()


def make_toy_bundle(folder: str | Path, threshold: float = THRESHOLD) -> Path:
    """Write the toy bundle into ``folder`` and return it."""
    meta = toy_meta(threshold)
    return write_bundle(folder, toy_graph_bytes(meta), meta)


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
