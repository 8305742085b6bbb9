"""int8 quantisation of the exported graph (``crossing_assist.export.quantize``), both modes,
on the tiny real policy of the graph tests: what is quantised, and that the result still
computes what the fp32 graph computes."""

import numpy as np
import onnxruntime as ort
import pytest
from onnx import numpy_helper

from crossing_assist.export.graph import GraphSpec, export_graph, model_bytes
from crossing_assist.export.quantize import float_activation_convs, quantize_convs
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
    assert len(model_bytes(q)) < 0.5 * len(model_bytes(fp32))


def test_static_mode_quantises_activations_except_the_first_and_the_head_convs(fp32):
    keep = float_activation_convs(fp32)
    convs = [n for n in fp32.graph.node if n.op_type == "Conv"]
    head = [n.name for n in convs if len(numpy_helper.to_array(conv_weights(fp32)[n.name]).shape) == 3]
    assert head and keep == [convs[0].name] + head
    x = frames(16, seed=3)
    q = quantize_convs(fp32, list(x), mode="static", batch=4)
    assert any(n.op_type == "QuantizeLinear" for n in q.graph.node)
    assert all(numpy_helper.to_array(w).dtype == np.int8 for w in conv_weights(q).values())
    p32, p8 = probs(fp32, x), probs(q, x)
    np.testing.assert_allclose(p8.sum(1), 1, atol=1e-5)
    assert np.abs(p8 - p32).max() < 0.1


def test_unknown_mode_is_refused(fp32):
    with pytest.raises(ValueError, match="valid: static, weights"):
        quantize_convs(fp32, [], mode="int4")
