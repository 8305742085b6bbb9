"""A tiny, deterministic bundle for testing the phone app (no torch; onnx.helper only).

The graph follows docs/contracts.md section 3 exactly (uint8 NHWC RGB ``frames`` in; the graph
resizes to ``input.size`` and normalises itself; outputs probs, entropy, mutual_info, variance,
votes), but its "policy" is a hand-made brightness detector: the frame is resized to
``size`` = (H, W) with W a multiple of 12, the normalised grey level of each of the 12 vertical
strips is a bin logit (times ``gain``), and the ``unknown`` logit is ``unknown_logit``.
A bright vertical bar in strip k therefore gives a confident ``k``; a uniform frame gives a
flat, uncertain distribution (high entropy). With ``mc_samples > 1`` a uniform noise term
(RandomUniformLike, as in the real MC-dropout graphs) is added to the logits of each sample,
so entropy, mutual information, variance and votes vary between runs.

Usage::

    python android_demo/tools/make_test_bundle.py OUT_DIR [--mc-samples 1] [--size 24 48]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from crossing_assist.actions import DEFAULT_FOV_DEG, get_space
from crossing_assist.bundle import BundleError, embedded_meta, write_bundle

N_ACTIONS = 13
MEAN = (0.485, 0.456, 0.406)
STD = (0.229, 0.224, 0.225)


def _const(name: str, value: np.ndarray) -> onnx.NodeProto:
    return helper.make_node("Constant", [], [name], value=numpy_helper.from_array(value, name=name + "_v"))


def build_graph(size: tuple[int, int], gain: float, unknown_logit: float, mc_samples: int,
                noise: float) -> onnx.GraphProto:
    """The ONNX graph: frames uint8 [N, H, W, 3] -> probs [N, 13] and the uncertainty outputs."""
    h, w = size
    if w % 12:
        raise ValueError(f"Invalid size: width {w} must be a multiple of 12")
    t = mc_samples
    f32 = np.float32
    nodes = [
        helper.make_node("Cast", ["frames"], ["x_f"], to=TensorProto.FLOAT),
        helper.make_node("Transpose", ["x_f"], ["x_nchw"], perm=[0, 3, 1, 2]),
        helper.make_node("Shape", ["x_nchw"], ["shape_in"]),
        _const("zero_i", np.array([0], np.int64)),
        _const("two_i", np.array([2], np.int64)),
        helper.make_node("Slice", ["shape_in", "zero_i", "two_i"], ["shape_nc"]),
        _const("hw", np.array([h, w], np.int64)),
        helper.make_node("Concat", ["shape_nc", "hw"], ["sizes"], axis=0),
        helper.make_node("Resize", ["x_nchw", "", "", "sizes"], ["x_small"], mode="linear",
                         coordinate_transformation_mode="half_pixel"),
        _const("scale255", np.array(1 / 255, f32)),
        helper.make_node("Mul", ["x_small", "scale255"], ["x_unit"]),
        _const("mean", np.array(MEAN, f32).reshape(1, 3, 1, 1)),
        _const("std", np.array(STD, f32).reshape(1, 3, 1, 1)),
        helper.make_node("Sub", ["x_unit", "mean"], ["x_c"]),
        helper.make_node("Div", ["x_c", "std"], ["x_norm"]),
        # grey level per column: mean over channels and rows -> [N, W]
        helper.make_node("ReduceMean", ["x_norm"], ["cols"], axes=[1, 2], keepdims=0),
        _const("strip_shape", np.array([0, 12, w // 12], np.int64)),
        helper.make_node("Reshape", ["cols", "strip_shape"], ["strips3"]),
        helper.make_node("ReduceMean", ["strips3"], ["strips"], axes=[2], keepdims=0),  # [N, 12]
        _const("gain", np.array(gain, f32)),
        helper.make_node("Mul", ["strips", "gain"], ["bin_logits"]),
        helper.make_node("Shape", ["bin_logits"], ["shape_b"]),
        _const("n_slice_end", np.array([1], np.int64)),
        helper.make_node("Slice", ["shape_b", "zero_i", "n_slice_end"], ["n_only"]),
        _const("one_i", np.array([1], np.int64)),
        helper.make_node("Concat", ["n_only", "one_i"], ["shape_n1"], axis=0),
        _const("unk", np.array([unknown_logit], f32)),
        helper.make_node("Expand", ["unk", "shape_n1"], ["unk_col"]),
        helper.make_node("Concat", ["unk_col", "bin_logits"], ["logits"], axis=1),  # [N, 13]
        # T samples folded into a leading axis: [T, N, 13]
        helper.make_node("Unsqueeze", ["logits", "zero_i"], ["logits1"]),
        _const("tiles", np.array([t, 1, 1], np.int64)),
        helper.make_node("Tile", ["logits1", "tiles"], ["logits_t"]),
    ]
    if noise > 0:
        nodes += [
            helper.make_node("RandomUniformLike", ["logits_t"], ["u"], low=0.0, high=float(noise)),
            helper.make_node("Add", ["logits_t", "u"], ["logits_s"]),
        ]
    else:
        nodes.append(helper.make_node("Identity", ["logits_t"], ["logits_s"]))
    nodes += [
        helper.make_node("Softmax", ["logits_s"], ["p_s"], axis=-1),
        helper.make_node("ReduceMean", ["p_s"], ["probs"], axes=[0], keepdims=0),
        _const("eps", np.array(1e-12, f32)),
        helper.make_node("Add", ["probs", "eps"], ["probs_e"]),
        helper.make_node("Log", ["probs_e"], ["log_p"]),
        helper.make_node("Mul", ["probs", "log_p"], ["plogp"]),
        helper.make_node("ReduceSum", ["plogp", "one_i"], ["neg_ent"], keepdims=0),
        helper.make_node("Neg", ["neg_ent"], ["entropy"]),
        helper.make_node("Add", ["p_s", "eps"], ["p_s_e"]),
        helper.make_node("Log", ["p_s_e"], ["log_ps"]),
        helper.make_node("Mul", ["p_s", "log_ps"], ["plogp_s"]),
        _const("minus_one_i", np.array([-1], np.int64)),
        helper.make_node("ReduceSum", ["plogp_s", "minus_one_i"], ["neg_ent_s"], keepdims=0),  # [T, N]
        helper.make_node("ReduceMean", ["neg_ent_s"], ["mean_neg_ent_s"], axes=[0], keepdims=0),
        helper.make_node("Add", ["entropy", "mean_neg_ent_s"], ["mi_raw"]),
        _const("zero_f", np.array(0.0, f32)),
        helper.make_node("Max", ["mi_raw", "zero_f"], ["mutual_info"]),
        helper.make_node("Sub", ["p_s", "probs"], ["dev"]),
        helper.make_node("Mul", ["dev", "dev"], ["dev2"]),
        helper.make_node("ReduceMean", ["dev2"], ["variance"], axes=[0], keepdims=0),
        helper.make_node("ArgMax", ["p_s"], ["amax"], axis=-1, keepdims=0),  # [T, N]
        helper.make_node("OneHot", ["amax", "depth", "onehot_values"], ["onehot"], axis=-1),
        helper.make_node("ReduceMean", ["onehot"], ["votes"], axes=[0], keepdims=0),
    ]
    inits = [numpy_helper.from_array(np.array(N_ACTIONS, np.int64), "depth"),
             numpy_helper.from_array(np.array([0.0, 1.0], f32), "onehot_values")]
    return helper.make_graph(
        nodes, "crossing_assist_test_bundle",
        [helper.make_tensor_value_info("frames", TensorProto.UINT8, ["N", "H", "W", 3])],
        [helper.make_tensor_value_info("probs", TensorProto.FLOAT, ["N", N_ACTIONS]),
         helper.make_tensor_value_info("entropy", TensorProto.FLOAT, ["N"]),
         helper.make_tensor_value_info("mutual_info", TensorProto.FLOAT, ["N"]),
         helper.make_tensor_value_info("variance", TensorProto.FLOAT, ["N", N_ACTIONS]),
         helper.make_tensor_value_info("votes", TensorProto.FLOAT, ["N", N_ACTIONS])],
        initializer=inits,
    )


def bundle_meta(size: tuple[int, int], mc_samples: int, entropy_threshold: float) -> dict:
    """bundle.json (schema 1) for the test graph."""
    space = get_space(N_ACTIONS)
    return {
        "schema_version": 1,
        "model_file": "model.onnx",
        "actions": {"n": N_ACTIONS, "names": list(space.names), "bins": [list(g) for g in space.groups]},
        "fov_deg": DEFAULT_FOV_DEG,
        "input": {"layout": "NHWC", "dtype": "uint8", "color": "RGB", "size": list(size),
                  "mean": list(MEAN), "std": list(STD)},
        "mc": {"samples": mc_samples, "p": 0.0},
        "calibration": {"temperature": 1.0,
                        "conformal": {"coverage": 0.9, "threshold": 0.05, "n_frames": 0},
                        "uncertainty": {"measure": "entropy", "threshold": entropy_threshold}},
        "precision": "fp32",
        "training": {"backbone": "none (brightness detector)", "head": "none", "data": "none", "counts": {}},
        "metrics": {},
        "package_version": "0.1.0",
        "provenance": {"command": "android_demo/tools/make_test_bundle.py", "created": "test"},
    }


def make_test_bundle(out_dir: str | Path, *, size: tuple[int, int] = (24, 48), gain: float = 4.0,
                     unknown_logit: float = 0.0, mc_samples: int = 1, noise: float = 0.0,
                     entropy_threshold: float = 1.2) -> Path:
    """Write the test bundle (model.onnx + bundle.json) atomically into ``out_dir``; returns it."""
    meta = bundle_meta(size, mc_samples, entropy_threshold)
    graph = build_graph(size, gain, unknown_logit, mc_samples, noise)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)],
                              producer_name="crossing_assist.android_demo")
    model.ir_version = 8
    helper.set_model_props(model, {"bundle_json": __import__("json").dumps(embedded_meta(meta)),
                                   "schema_version": "1"})
    onnx.checker.check_model(model)
    return write_bundle(out_dir, model.SerializeToString(), meta)


#: The geometry block the app's tests give a schema-1 bundle (bundle.json schema 2, issue 12):
#: distinct default FOVs per orientation, so the tests see which one the app chose. The test graph
#: resizes whatever it gets to its canvas, hence ``fit: stretch``.
TEST_GEOMETRY = {"fit": "stretch", "strips": "frame", "camera_fov_deg": {"landscape": 67.0, "portrait": 53.0},
                 "train_fov_deg": 67.0}


def schema2_copy(bundle_dir: str | Path, out_dir: str | Path, geometry: dict | None = None) -> Path:
    """A copy of a bundle whose bundle.json is schema 2 (for the app only: same model bytes).

    A schema-1 bundle gets ``geometry`` (default :data:`TEST_GEOMETRY`) and ``fov_deg`` =
    its landscape FOV; a schema-2 bundle is copied as it is."""
    import json
    import shutil

    src, out = Path(bundle_dir), Path(out_dir)
    meta = json.loads((src / "bundle.json").read_text())
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src / meta["model_file"], out / meta["model_file"])
    if meta["schema_version"] < 2:
        geom = geometry or TEST_GEOMETRY
        meta = {**meta, "schema_version": 2, "geometry": geom, "fov_deg": geom["camera_fov_deg"]["landscape"]}
    tmp = out / "bundle.json.tmp"
    tmp.write_text(json.dumps(meta, indent=2) + "\n")
    tmp.replace(out / "bundle.json")
    return out


def deterministic_copy(bundle_dir: str | Path, out_dir: str | Path) -> Path:
    """A copy of a bundle whose MC-dropout noise is a constant (every unit kept), so that two
    runtimes (onnxruntime in Python, onnxruntime-web in the browser) must agree number for number.

    Each ``RandomUniformLike(x)`` becomes ``x * 0 + 0.999`` (same shape; at or above any drop
    probability < 0.999, so the dropout masks keep everything). Everything else is untouched."""
    import json

    src = Path(bundle_dir)
    meta = json.loads((src / "bundle.json").read_text())
    model = onnx.load(str(src / meta["model_file"]))
    nodes = []
    for node in model.graph.node:
        if node.op_type != "RandomUniformLike":
            nodes.append(node)
            continue
        x, y = node.input[0], node.output[0]
        nodes += [_const(y + "_zero", np.array(0.0, np.float32)), _const(y + "_keep", np.array(0.999, np.float32)),
                  helper.make_node("Mul", [x, y + "_zero"], [y + "_z"]),
                  helper.make_node("Add", [y + "_z", y + "_keep"], [y])]
    del model.graph.node[:]
    model.graph.node.extend(nodes)
    return write_bundle(out_dir, model.SerializeToString(), meta)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--size", type=int, nargs=2, default=(24, 48), metavar=("H", "W"))
    ap.add_argument("--gain", type=float, default=4.0)
    ap.add_argument("--mc-samples", type=int, default=1)
    ap.add_argument("--noise", type=float, default=0.0)
    args = ap.parse_args(argv)
    try:
        path = make_test_bundle(args.out_dir, size=tuple(args.size), gain=args.gain,
                                mc_samples=args.mc_samples, noise=args.noise)
    except (BundleError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
