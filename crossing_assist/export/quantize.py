"""int8: the convolutions' weights stored int8, their activations int8 where it pays.

Two modes (``crossing-export --int8 --int8-mode static|weights``):

* ``static`` (default): onnxruntime's static QDQ quantisation of the backbone's convolutions,
  weights per channel and activations per tensor, ranges from the 99.99th percentile of the
  activations on real frames. The first convolution (it reads the normalised image) and the
  head's 1-D convolutions (on row-pooled features, where a max over rows meets a per-tensor
  range) keep float activations.
* ``weights``: every convolution keeps float activations; only its weights are stored int8.
  The file is as small and accuracy is fp32's, but onnxruntime keeps the
  ``DequantizeLinear`` nodes: on the default model it ran 2.4x slower than fp32 (x86).

Weights kept out of static QDQ are stored int8 all the same (symmetric, per output channel;
the head's per input channel, as its inputs are a row mean and a row max of very different
scale) behind a ``DequantizeLinear``. The resize/normalise front, the fully connected layers,
the random masks and the softmax/log tail stay float32: quantising the tail made mutual
information negative in a trial, and it is a negligible share of the compute. What each mode
cost on the default model is in docs/export.md.
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
    """Return an int8 copy of ``model`` (onnx.ModelProto): its Conv weights int8 and, in
    ``static`` mode, the backbone's Conv activations too (module docstring).

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

    keep_float = float_activation_convs(model)
    logging.getLogger("root").setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory(prefix="crossing-int8-") as tmp:
        src, dst = Path(tmp) / "fp32.onnx", Path(tmp) / "int8.onnx"
        onnx.save_model(model, str(src))
        with contextlib.redirect_stdout(io.StringIO()):  # the calibrator prints progress to stdout
            quantize_static(
                str(src), str(dst), Reader(frames, batch),
                quant_format=QuantFormat.QDQ, op_types_to_quantize=["Conv"], per_channel=True,
                nodes_to_exclude=keep_float,
                activation_type=QuantType.QInt8, weight_type=QuantType.QInt8,
                calibrate_method=CalibrationMethod.Percentile,
                extra_options={"ActivationSymmetric": False, "WeightSymmetric": True, "CalibPercentile": PERCENTILE},
            )
        out = onnx.load_model(str(dst))
    int8_weights(out, keep_float)
    del out.metadata_props[:]
    for p in model.metadata_props:
        e = out.metadata_props.add()
        e.key, e.value = p.key, p.value
    return out


def _conv_weights(model: Any) -> dict[str, tuple[Any, Any]]:
    """Conv node name -> (node, its float weight initializer) for convs with a constant weight."""
    inits = {i.name: i for i in model.graph.initializer}
    return {n.name: (n, inits[n.input[1]]) for n in model.graph.node
            if n.op_type == "Conv" and len(n.input) > 1 and n.input[1] in inits}


def float_activation_convs(model: Any) -> list[str]:
    """Names of the convs that keep float activations in ``static`` mode: the first and the
    1-D ones (the head's, on row-pooled features)."""
    convs = _conv_weights(model)
    order = [n.name for n in model.graph.node if n.name in convs]
    return [n for i, n in enumerate(order) if i == 0 or len(convs[n][1].dims) == 3]


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
