"""int8: the convolutions' weights stored int8, their activations int8 where it pays.

Two modes (``crossing-export --int8 --int8-mode static|weights``):

* ``static`` (default): onnxruntime's static QDQ quantisation of the backbone proper (after
  its first convolution, up to its last 2-D convolution and that one's activation): the
  convolutions, the residual ``Add`` nodes and the ``Clip``/``Relu`` activations, weights int8
  per output channel (symmetric), activations **uint8** per tensor (asymmetric), ranges from
  the 99.99th percentile of the activations on real frames. Quantising the ``Add`` and
  activation nodes too lets onnxruntime fuse every backbone convolution into a
  ``QLinearConv``/``QLinearAdd`` chain that stays int8 from the first block to the last; uint8
  activations (U8S8) are what its x86 kernels are fast for. The first convolution (it reads
  the normalised image) and the head (row-pooled features, where a max over rows meets a
  per-tensor range) keep float weights and activations: a ``DequantizeLinear`` in front of a
  float weight is not folded by onnxruntime and runs on every frame.
* ``weights``: every convolution keeps float activations; only its weights are stored int8.
  The file is as small and accuracy is fp32's, but onnxruntime keeps the
  ``DequantizeLinear`` nodes: on the default model it ran 2.4x slower than fp32 (x86).

The resize/normalise front, the fully connected layers, the random masks and the
softmax/log tail stay float32: quantising the tail made mutual information negative in a
trial, and it is a negligible share of the compute. What each choice cost, measured with
onnxruntime's profiler (``benchmarks/int8_speed.py``), is in docs/export.md.
"""

from __future__ import annotations

import contextlib
import io
import logging
import tempfile
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from crossing_assist.bundle import INPUT_NAME

PERCENTILE = 99.99


class _Frames:
    """onnxruntime CalibrationDataReader over batches of same-shape uint8 frames."""

    def __init__(self, frames: Sequence[np.ndarray], batch: int):
        self._it: Iterator[dict[str, np.ndarray]] = iter(
            {INPUT_NAME: np.ascontiguousarray(np.stack(frames[i:i + batch]))}
            for i in range(0, len(frames), batch))

    def get_next(self) -> dict[str, np.ndarray] | None:
        return next(self._it, None)

    def rewind(self) -> None:  # not needed by MinMax; present for the reader protocol
        pass


INT8_MODES = ("static", "weights")


def quantize_convs(model: Any, frames: Sequence[np.ndarray], *, mode: str = "static", batch: int = 8) -> Any:
    """Return an int8 copy of ``model`` (onnx.ModelProto): in ``weights`` mode every Conv
    weight int8; in ``static`` mode the backbone proper in int8, weights and activations
    (module docstring).

    ``frames``: calibration frames (H×W×3 uint8 RGB, one shape), e.g. 64-200 real frames
    (unused in ``weights`` mode). The metadata of ``model`` is carried over.
    """
    import onnx

    if mode not in INT8_MODES:
        raise ValueError(f"Invalid int8 mode {mode!r}; valid: {', '.join(INT8_MODES)}")
    if mode == "weights":
        out = onnx.ModelProto()
        out.CopyFrom(model)
        int8_weights(out, list(_conv_weights(out)))
        return out
    import onnxruntime as ort
    from onnxruntime.quantization import (CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType,
                                          quantize_static)

    if len(frames) == 0:
        raise ValueError("int8 quantisation needs calibration frames; pass --calib-data")
    shapes = {np.shape(f) for f in frames}
    if len(shapes) != 1:
        frames = [f for f in frames if np.shape(f) == np.shape(frames[0])]

    # The percentile calibrator stacks all batches: they must have one size.
    batch = min(batch, len(frames))
    frames = frames[: len(frames) // batch * batch]

    class Reader(_Frames, CalibrationDataReader):
        pass

    model = _named(model)
    quantize = backbone_nodes(model)
    logging.getLogger("root").setLevel(logging.ERROR)
    ort.set_default_logger_severity(3)   # the calibrator's batch of 8 meets value_info of batch 1: warnings only
    with tempfile.TemporaryDirectory(prefix="crossing-int8-") as tmp:
        src, dst = Path(tmp) / "fp32.onnx", Path(tmp) / "int8.onnx"
        onnx.save_model(model, str(src))
        with contextlib.redirect_stdout(io.StringIO()):  # the calibrator prints progress to stdout
            quantize_static(
                str(src), str(dst), Reader(frames, batch),
                quant_format=QuantFormat.QDQ, op_types_to_quantize=list(STATIC_OPS), per_channel=True,
                nodes_to_quantize=quantize,
                activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                calibrate_method=CalibrationMethod.Percentile,
                extra_options={"ActivationSymmetric": False, "WeightSymmetric": True, "CalibPercentile": PERCENTILE},
            )
        out = onnx.load_model(str(dst))
    del out.metadata_props[:]
    for p in model.metadata_props:
        e = out.metadata_props.add()
        e.key, e.value = p.key, p.value
    return out


# Node types quantised in ``static`` mode (inside the backbone only): with the activations and
# the residual adds quantised, onnxruntime fuses each Conv's QDQ pairs into a QLinearConv.
STATIC_OPS = ("Conv", "Add", "Clip", "Relu")


def _named(model: Any) -> Any:
    """``model``, or a copy whose unnamed nodes got unique names (the quantiser selects by name)."""
    import onnx

    if all(n.name for n in model.graph.node) and len({n.name for n in model.graph.node}) == len(model.graph.node):
        return model
    out = onnx.ModelProto()
    out.CopyFrom(model)
    for i, n in enumerate(out.graph.node):
        n.name = f"{n.op_type}_{i}_{n.name}"
    return out


def backbone_nodes(model: Any) -> list[str]:
    """Names of the ``STATIC_OPS`` nodes of the backbone proper: descendants of the first
    convolution (itself excluded) that lead to the last 2-D convolution, that convolution and
    the activation right after it. The head, the front and the tail are outside."""
    convs = _conv_weights(model)
    conv2d = [n.name for n in model.graph.node if n.name in convs and len(convs[n.name][1].dims) == 4]
    if not conv2d:
        return []
    by_name = {n.name: n for n in model.graph.node}
    producer = {o: n for n in model.graph.node for o in n.output}

    def ancestors(name: str) -> set[str]:
        seen, todo = set(), [by_name[name]]
        while todo:
            for i in todo.pop().input:
                p = producer.get(i)
                if p is not None and p.name not in seen:
                    seen.add(p.name)
                    todo.append(p)
        return seen

    first, last = conv2d[0], conv2d[-1]
    inside = (ancestors(last) | {last}) - ancestors(first) - {first}
    tail = by_name[last].output[0]
    users = [n for n in model.graph.node if tail in n.input]
    if len(users) == 1 and users[0].op_type in ("Clip", "Relu"):
        inside.add(users[0].name)
    return [n.name for n in model.graph.node if n.name in inside and n.op_type in STATIC_OPS]


def _conv_weights(model: Any) -> dict[str, tuple[Any, Any]]:
    """Conv node name -> (node, its float weight initializer) for convs with a constant weight."""
    inits = {i.name: i for i in model.graph.initializer}
    return {n.name: (n, inits[n.input[1]]) for n in model.graph.node
            if n.op_type == "Conv" and len(n.input) > 1 and n.input[1] in inits}


def float_activation_convs(model: Any) -> list[str]:
    """Names of the convs that keep float weights and activations in ``static`` mode: those
    outside the backbone proper (the first, and the head's 1-D ones on row-pooled features)."""
    inside = set(backbone_nodes(model))
    return [n.name for n in model.graph.node if n.name in _conv_weights(model) and n.name not in inside]


def int8_weights(model: Any, names: Sequence[str]) -> None:
    """In place: store the weights of convs ``names`` as int8 (symmetric, per channel) behind
    a ``DequantizeLinear``; their activations stay float."""
    from onnx import helper, numpy_helper

    convs = _conv_weights(model)
    added = []
    for name in names:
        node, init = convs[name]
        w = numpy_helper.to_array(init).astype(np.float32)
        # Per output channel; the head's 1-D convs per *input* channel: their inputs are the
        # row mean and row max of the features, whose weights differ in scale.
        axis = 1 if w.ndim == 3 else 0
        amax = np.abs(np.moveaxis(w, axis, 0).reshape(w.shape[axis], -1)).max(1)
        scale = np.where(amax > 0, amax / 127.0, 1.0).astype(np.float32)
        shape = [1] * w.ndim
        shape[axis] = -1
        q = np.clip(np.round(w / scale.reshape(shape)), -127, 127).astype(np.int8)
        base = init.name
        model.graph.initializer.remove(init)
        model.graph.initializer.extend([numpy_helper.from_array(q, f"{base}_int8"),
                                        numpy_helper.from_array(scale, f"{base}_scale"),
                                        numpy_helper.from_array(np.zeros(len(scale), np.int8), f"{base}_zero")])
        added.append(helper.make_node("DequantizeLinear", [f"{base}_int8", f"{base}_scale", f"{base}_zero"], [base],
                                      name=f"{base}_dequantize", axis=axis))
    nodes = added + list(model.graph.node)  # constants first keeps the graph topologically sorted
    del model.graph.node[:]
    model.graph.node.extend(nodes)
