"""The one toy bundle builder (onnx.helper, no torch) for the runtime's and the phone app's tests.

The toy "policy" finds the brightest vertical strip. Its graph follows docs/contracts.md section 3
(uint8 NHWC RGB ``frames`` in; outputs probs, entropy, mutual_info, variance, votes): it resizes the
frame to ``size`` = (H, W) (W a multiple of 12), normalises it with ``(x / 255 - mean) / std``,
averages each of the 12 vertical strips over rows and channels, and gives bin ``k`` the logit
``gain * strip_k`` (``gain * (strip_k - mean over strips)`` with ``centre``); ``unknown`` gets
``unknown_logit``. A bright bar on a dark frame -> that strip's bin, confidently; a flat or noisy
frame -> near-uniform, high-entropy probabilities.

MC sampling is real: the logits are copied ``samples`` times; with ``drop_p > 0`` each copy is
masked by ``RandomUniformLike >= drop_p`` (inverted dropout, as in the exported models) and with
``noise > 0`` uniform noise in [0, noise) is added, so the samples vary from run to run.

The metadata is written by :func:`crossing_assist.bundle.make_meta` (``geometry=None``: schema 1).
Presets: :data:`RUNTIME_TOY` (the runtime tests' toy) and :data:`APP_TOY` (the phone app's).
:func:`deterministic_copy` makes any bundle's MC noise constant (the app's parity tests).

    python -m crossing_assist.testing.toy_bundle OUT_DIR [--app] [--mc-samples 1] [--size 24 48]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crossing_assist.bundle import (
    BundleError,
    Calibration,
    ConformalSpec,
    InputSpec,
    McSpec,
    UncertaintySpec,
    graph_metadata,
    make_meta,
    write_bundle,
)
from crossing_assist.geometry import Geometry

N_ACTIONS = 13
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


@dataclass(frozen=True)
class Toy:
    """What the toy graph does and what its bundle.json says (module docstring)."""

    size: tuple[int, int] = (24, 48)
    mean: tuple[float, float, float] = (0.5, 0.5, 0.5)
    std: tuple[float, float, float] = (0.25, 0.25, 0.25)
    gain: float = 10.0
    centre: bool = True
    unknown_logit: float = 0.0
    samples: int = 8
    drop_p: float = 0.05
    noise: float = 0.0
    threshold: float = 1.0          # the gate's entropy threshold (nats)
    portrait_threshold: float | None = None  # the same for portrait frames (None: threshold)
    narrow_threshold: float | None = None    # portrait frames at most narrow_fov_deg across (None: none)
    narrow_fov_deg: float | None = None
    wide_fov_deg: float | None = None        # by the camera's width: narrower frames take portrait_threshold
    geometry: Geometry | None = None  # None: a schema-1 bundle
    name: str = "toy-bright-strip"

    def __post_init__(self) -> None:
        if self.size[1] % 12:
            raise ValueError(f"Invalid toy size {self.size}: the width must be a multiple of 12")
        if self.samples < 1 or not 0.0 <= self.drop_p < 1.0 or self.noise < 0:
            raise ValueError(f"Invalid toy: samples {self.samples} (>= 1), drop_p {self.drop_p} (0..1), "
                             f"noise {self.noise} (>= 0)")


#: The runtime tests' toy: a gain of 40 grey levels per unit, strips relative to their mean,
#: 8 samples with real dropout (p = 0.05), gate threshold 1 nat.
RUNTIME_TOY = Toy()
#: The phone app's toy: ImageNet normalisation, absolute strips with gain 4, one deterministic
#: sample, gate threshold 1.2 nats.
APP_TOY = Toy(mean=IMAGENET_MEAN, std=IMAGENET_STD, gain=4.0, centre=False, samples=1, drop_p=0.0,
              threshold=1.2, name="none (brightness detector)")


def toy_meta(toy: Toy = RUNTIME_TOY) -> dict:
    """The toy's bundle.json dict (13 actions), written by :func:`crossing_assist.bundle.make_meta`."""
    return make_meta(
        n_actions=N_ACTIONS,
        input=InputSpec(size=toy.size, mean=toy.mean, std=toy.std),
        geometry=toy.geometry,
        mc=McSpec(toy.samples, toy.drop_p),
        calibration=Calibration(1.0, ConformalSpec(0.9, 0.05, 0), UncertaintySpec(
            "entropy", toy.threshold, toy.portrait_threshold, narrow_threshold=toy.narrow_threshold,
            narrow_fov_deg=toy.narrow_fov_deg, wide_fov_deg=toy.wide_fov_deg)),
        training={"backbone": toy.name, "head": "none", "data": "none", "counts": {}},
        provenance={"command": "crossing_assist.testing.toy_bundle", "created": "test"},
    )


def toy_model_bytes(toy: Toy = RUNTIME_TOY, meta: dict | None = None) -> bytes:
    """The toy ONNX model (opset 17, runs in onnxruntime and onnxruntime-web) with ``meta``
    (default :func:`toy_meta`) embedded as the exporter embeds it."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    def const(name: str, value, dtype=np.float32) -> onnx.NodeProto:
        return helper.make_node("Constant", [], [name],
                                value=numpy_helper.from_array(np.asarray(value, dtype=dtype), name + "_v"))

    h, w = toy.size
    n = helper.make_node
    nodes = [
        n("Cast", ["frames"], ["x_f"], to=TensorProto.FLOAT),
        n("Transpose", ["x_f"], ["x_nchw"], perm=[0, 3, 1, 2]),
        n("Shape", ["x_nchw"], ["shape_in"]),
        const("zero_i", [0], np.int64), const("one_i", [1], np.int64), const("two_i", [2], np.int64),
        n("Slice", ["shape_in", "zero_i", "two_i"], ["shape_nc"]),
        const("hw", [h, w], np.int64),
        n("Concat", ["shape_nc", "hw"], ["sizes"], axis=0),
        n("Resize", ["x_nchw", "", "", "sizes"], ["x_small"], mode="linear",
          coordinate_transformation_mode="half_pixel"),
        const("scale255", 1 / 255), n("Mul", ["x_small", "scale255"], ["x_unit"]),
        const("mean", np.reshape(toy.mean, (1, 3, 1, 1))), const("std", np.reshape(toy.std, (1, 3, 1, 1))),
        n("Sub", ["x_unit", "mean"], ["x_c"]), n("Div", ["x_c", "std"], ["x_norm"]),
        n("ReduceMean", ["x_norm"], ["cols"], axes=[1, 2], keepdims=0),              # [N, W]
        const("strip_shape", [0, 12, w // 12], np.int64),
        n("Reshape", ["cols", "strip_shape"], ["strips3"]),
        n("ReduceMean", ["strips3"], ["strips"], axes=[2], keepdims=0),              # [N, 12]
    ]
    if toy.centre:
        nodes += [n("ReduceMean", ["strips"], ["strip_avg"], axes=[1], keepdims=1),
                  n("Sub", ["strips", "strip_avg"], ["strips_rel"])]
    nodes += [
        const("gain", toy.gain), n("Mul", ["strips_rel" if toy.centre else "strips", "gain"], ["bin_logits"]),
        n("Shape", ["bin_logits"], ["shape_b"]),
        n("Slice", ["shape_b", "zero_i", "one_i"], ["n_only"]),
        n("Concat", ["n_only", "one_i"], ["shape_n1"], axis=0),
        const("unk", [toy.unknown_logit]), n("Expand", ["unk", "shape_n1"], ["unk_col"]),
        n("Concat", ["unk_col", "bin_logits"], ["logits"], axis=1),                  # [N, 13]
        n("Unsqueeze", ["logits", "zero_i"], ["logits1"]),
        const("tiles", [toy.samples, 1, 1], np.int64),
        n("Tile", ["logits1", "tiles"], ["s0"]),                                      # [T, N, 13]
    ]
    last = "s0"
    if toy.drop_p > 0:
        nodes += [n("RandomUniformLike", [last], ["u_drop"], dtype=TensorProto.FLOAT),
                  const("p", toy.drop_p), n("GreaterOrEqual", ["u_drop", "p"], ["keep"]),
                  n("Cast", ["keep"], ["keep_f"], to=TensorProto.FLOAT), n("Mul", [last, "keep_f"], ["s_kept"]),
                  const("inv_keep", 1.0 / (1.0 - toy.drop_p)), n("Mul", ["s_kept", "inv_keep"], ["s1"])]
        last = "s1"
    if toy.noise > 0:
        nodes += [n("RandomUniformLike", [last], ["u_noise"], low=0.0, high=float(toy.noise)),
                  n("Add", [last, "u_noise"], ["s2"])]
        last = "s2"
    nodes += [
        n("Softmax", [last], ["p_s"], axis=-1),
        n("ReduceMean", ["p_s"], ["probs"], axes=[0], keepdims=0),
        const("eps", 1e-12), const("minus_one_i", [-1], np.int64), const("zero_f", 0.0),
        n("Add", ["probs", "eps"], ["probs_e"]), n("Log", ["probs_e"], ["log_p"]),
        n("Mul", ["probs", "log_p"], ["plogp"]),
        n("ReduceSum", ["plogp", "minus_one_i"], ["neg_ent"], keepdims=0), n("Neg", ["neg_ent"], ["entropy"]),
        n("Add", ["p_s", "eps"], ["p_s_e"]), n("Log", ["p_s_e"], ["log_ps"]), n("Mul", ["p_s", "log_ps"], ["plogp_s"]),
        n("ReduceSum", ["plogp_s", "minus_one_i"], ["neg_ent_s"], keepdims=0),       # [T, N]
        n("ReduceMean", ["neg_ent_s"], ["mean_neg_ent_s"], axes=[0], keepdims=0),
        n("Add", ["entropy", "mean_neg_ent_s"], ["mi_raw"]), n("Max", ["mi_raw", "zero_f"], ["mutual_info"]),
        n("Sub", ["p_s", "probs"], ["dev"]), n("Mul", ["dev", "dev"], ["dev2"]),
        n("ReduceMean", ["dev2"], ["variance"], axes=[0], keepdims=0),
        n("ArgMax", ["p_s"], ["amax"], axis=-1, keepdims=0),                          # [T, N]
        const("depth", N_ACTIONS, np.int64), const("onehot_values", [0.0, 1.0]),
        n("OneHot", ["amax", "depth", "onehot_values"], ["onehot"], axis=-1),
        n("ReduceMean", ["onehot"], ["votes"], axes=[0], keepdims=0),
    ]
    f, a = TensorProto.FLOAT, N_ACTIONS
    graph = helper.make_graph(
        nodes, "crossing_assist_toy",
        [helper.make_tensor_value_info("frames", TensorProto.UINT8, ["N", "H", "W", 3])],
        [helper.make_tensor_value_info("probs", f, ["N", a]), helper.make_tensor_value_info("entropy", f, ["N"]),
         helper.make_tensor_value_info("mutual_info", f, ["N"]),
         helper.make_tensor_value_info("variance", f, ["N", a]), helper.make_tensor_value_info("votes", f, ["N", a])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="crossing_assist.toy")
    model.ir_version = 8
    helper.set_model_props(model, graph_metadata(toy_meta(toy) if meta is None else meta))
    onnx.checker.check_model(model)
    return model.SerializeToString()


def make_toy_bundle(folder: str | Path, toy: Toy = RUNTIME_TOY, **changes) -> Path:
    """Write the toy bundle (``toy`` with ``changes`` applied, e.g. ``threshold=2.0``) into
    ``folder`` atomically and return it."""
    toy = dataclasses.replace(toy, **changes)
    meta = toy_meta(toy)
    return write_bundle(folder, toy_model_bytes(toy, meta), meta)


def deterministic_copy(bundle_dir: str | Path, out_dir: str | Path) -> Path:
    """A copy of a bundle whose MC-dropout noise is a constant (every unit kept), so that two
    runtimes (onnxruntime in Python, onnxruntime-web in the browser) must agree number for number.

    Each ``RandomUniformLike(x)`` becomes ``x * 0 + 0.999`` (same shape; at or above any drop
    probability < 0.999, so the dropout masks keep everything). Everything else, the embedded
    metadata included, is untouched."""
    import json

    import onnx
    from onnx import helper, numpy_helper

    src = Path(bundle_dir)
    meta = json.loads((src / "bundle.json").read_text())
    model = onnx.load(str(src / meta["model_file"]))
    nodes = []
    for node in model.graph.node:
        if node.op_type != "RandomUniformLike":
            nodes.append(node)
            continue
        x, y = node.input[0], node.output[0]
        consts = [helper.make_node("Constant", [], [y + name], value=numpy_helper.from_array(
            np.asarray(v, np.float32), y + name + "_v")) for name, v in (("_zero", 0.0), ("_keep", 0.999))]
        nodes += consts + [helper.make_node("Mul", [x, y + "_zero"], [y + "_z"]),
                           helper.make_node("Add", [y + "_z", y + "_keep"], [y])]
    del model.graph.node[:]
    model.graph.node.extend(nodes)
    return write_bundle(out_dir, model.SerializeToString(), meta)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--app", action="store_true", help="the phone app's toy (default: the runtime tests')")
    ap.add_argument("--size", type=int, nargs=2, metavar=("H", "W"))
    ap.add_argument("--gain", type=float)
    ap.add_argument("--mc-samples", type=int, dest="samples")
    ap.add_argument("--noise", type=float)
    args = ap.parse_args(argv)
    changes = {k: v for k, v in vars(args).items() if k in ("gain", "samples", "noise") and v is not None}
    if args.size:
        changes["size"] = tuple(args.size)
    try:
        path = make_toy_bundle(args.out_dir, APP_TOY if args.app else RUNTIME_TOY, **changes)
    except (BundleError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
