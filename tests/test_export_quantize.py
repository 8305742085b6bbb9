"""int8 quantisation of the exported graph (``crossing_assist.export.quantize``), both modes,
on the tiny real policy of the graph tests: what is quantised, and that the result still
computes what the fp32 graph computes."""

import os
import tempfile
from collections import Counter

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from onnx import numpy_helper
from torch import nn

from crossing_assist.export.graph import GraphSpec, export_graph, model_bytes
from crossing_assist.export.quantize import backbone_nodes, float_activation_convs, quantize_convs
from crossing_assist.models.backbones import Backbone, BackboneFacts
from crossing_assist.models.heads import create_head
from crossing_assist.models.policy import Policy, policy_config
from tests.test_export_graph import MEAN, STD, frames, tiny_policy

DET = GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=1, p=0.0)


@pytest.fixture(scope="module")
def fp32():
    return export_graph(tiny_policy(), DET)


def probs(model, x):
    return ort.InferenceSession(model_bytes(model)).run(["probs"], {"frames": x})[0]


def conv_weights(model):
    inits = {i.name: i for i in model.graph.initializer}
    producers = {o: n for n in model.graph.node for o in n.output}
    out = {}
    for n in model.graph.node:
        if n.op_type == "Conv":
            w = n.input[1]
            out[n.name] = inits.get(w) or next(inits[i] for i in producers[w].input if i in inits
                                               and inits[i].data_type in (2, 3))  # int8 / uint8
    return out


def test_weights_mode_stores_every_conv_weight_int8_and_keeps_fp32_outputs(fp32):
    q = quantize_convs(fp32, [], mode="weights")
    weights = conv_weights(q)
    assert len(weights) == len(conv_weights(fp32)) >= 4
    assert all(numpy_helper.to_array(w).dtype == np.int8 for w in weights.values())
    assert not any(n.op_type == "QuantizeLinear" for n in q.graph.node)  # activations stay float
    x = frames(6)
    np.testing.assert_allclose(probs(q, x), probs(fp32, x), atol=0.02)
    assert len(model_bytes(q)) < 0.6 * len(model_bytes(fp32))   # tiny model: graph overhead is a large share


class _Residual(nn.Module):
    def __init__(self, c: int):
        super().__init__()
        self.body = nn.Sequential(nn.Conv2d(c, 2 * c, 1), nn.BatchNorm2d(2 * c, momentum=None), nn.ReLU6(),
                                  nn.Conv2d(2 * c, 2 * c, 3, padding=1, groups=2 * c),
                                  nn.BatchNorm2d(2 * c, momentum=None), nn.ReLU6(),
                                  nn.Conv2d(2 * c, c, 1), nn.BatchNorm2d(c, momentum=None))

    def forward(self, x):
        return x + self.body(x)


def residual_policy(seed: int = 0) -> Policy:
    """A tiny MobileNet-like backbone: ReLU6 (Clip), a depthwise conv and a residual Add."""
    torch.manual_seed(seed)
    blocks = [nn.Sequential(nn.Conv2d(3, 8, 3, stride=2, padding=1), nn.BatchNorm2d(8, momentum=None), nn.ReLU6()),
              _Residual(8),
              nn.Sequential(nn.Conv2d(8, 16, 3, stride=2, padding=1), nn.BatchNorm2d(16, momentum=None), nn.ReLU6())]
    backbone = Backbone(blocks, 16, BackboneFacts("tiny_res", (32, 32), MEAN, STD, "none", "test"))
    rng = np.random.default_rng(seed)
    backbone.train()
    with torch.no_grad():
        for _ in range(4):
            backbone(torch.from_numpy(rng.normal(0, 1, (16, 3, 32, 32)).astype(np.float32)).cumsum(-1) / 4)
    return Policy(backbone, create_head("spatial", 16, 13, p=0.5),
                  policy_config(backbone, "spatial", 13, input_size=(32, 32))).eval()


def optimised_ops(model) -> Counter:
    """Node types of ``model`` after onnxruntime's full graph optimisation on this CPU."""
    with tempfile.TemporaryDirectory() as tmp:
        so = ort.SessionOptions()
        so.optimized_model_filepath = os.path.join(tmp, "opt.onnx")
        so.log_severity_level = 3
        ort.InferenceSession(model_bytes(model), so, providers=["CPUExecutionProvider"])
        return Counter(n.op_type for n in onnx.load(so.optimized_model_filepath).graph.node)


def test_static_mode_runs_the_backbone_int8_end_to_end_and_keeps_first_and_head_float():
    fp32 = export_graph(residual_policy(), DET)
    convs = [n for n in fp32.graph.node if n.op_type == "Conv"]
    head = [n.name for n in convs if len(numpy_helper.to_array(conv_weights(fp32)[n.name]).shape) == 3]
    assert head and float_activation_convs(fp32) == [convs[0].name] + head
    inside = Counter(n.op_type for n in fp32.graph.node if n.name in backbone_nodes(fp32))
    assert inside == {"Conv": 4, "Clip": 4, "Add": 1}  # the stem's Clip too, not the tail's
    x = frames(16, seed=3)
    q = quantize_convs(fp32, list(x), mode="static", batch=4)
    weights = conv_weights(q)
    dtypes = {n: numpy_helper.to_array(weights[n]).dtype for n in weights}
    assert all(dtypes[n] == np.float32 for n in float_activation_convs(fp32))  # no per-frame dequantise
    assert sum(d == np.int8 for d in dtypes.values()) == 4
    acts = {i.name: i.data_type for i in q.graph.initializer if i.name.endswith("_zero_point")}
    assert onnx.TensorProto.UINT8 in acts.values()  # U8S8: uint8 activations, int8 weights
    # onnxruntime fuses every backbone conv and the residual add: no QDQ pair is left unfused
    # inside: one Quantize after the float stem conv, and a Dequantize for each of the head's
    # two readers of the features (row mean, row max).
    ops = optimised_ops(q)
    assert ops["QLinearConv"] == 4 and ops["QLinearAdd"] == 1
    assert ops["QuantizeLinear"] == 1 and ops["DequantizeLinear"] == 2
    p32, p8 = probs(fp32, x), probs(q, x)
    np.testing.assert_allclose(p8.sum(1), 1, atol=1e-5)
    assert np.abs(p8 - p32).max() < 0.1


def test_unknown_mode_is_refused(fp32):
    with pytest.raises(ValueError, match="valid: static, weights"):
        quantize_convs(fp32, [], mode="int4")
