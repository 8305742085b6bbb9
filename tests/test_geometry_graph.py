"""The letterbox inside the ONNX graph follows crossing_assist.geometry exactly, the head reads
the 12 strips of the frame inside the content window, and ONNX == PyTorch on portrait frames."""

import warnings

import numpy as np
import onnxruntime as ort
import pytest
import torch
import torch.nn.functional as F
from torch import nn

from crossing_assist.export.exporter import parity_check
from crossing_assist.export.graph import MAX_SIDE, BundleGraph, GraphSpec, export_graph, model_bytes
from crossing_assist.geometry import content_window, letterbox_box
from crossing_assist.models.backbones import create_backbone
from crossing_assist.models.heads import N_BINS, create_head
from crossing_assist.models.policy import Policy, policy_config

CANVAS = (48, 64)                       # (H, W): 4:3 landscape
MEAN, STD = (0.485, 0.456, 0.406), (0.229, 0.224, 0.225)
PAD = (124, 116, 104)
# (H, W) of frames of several aspects: 4:3, 16:9, 3:4, 9:16, square, 7:1 and 1:7
SHAPES = [(120, 160), (90, 160), (160, 120), (160, 90), (100, 100), (16, 112), (112, 16), (37, 53)]


class _Pre(BundleGraph):
    """Only the graph's preprocessing: (canvas, window)."""

    def forward(self, frames):
        return self.preprocess(frames)


@pytest.fixture(scope="module", params=["spatial", "spatial_fine", "spatial_strips"])
def policy(request):
    torch.manual_seed(0)
    backbone = create_backbone("mobilenet_v3_small", weights="none")
    with torch.no_grad():   # batch-norm statistics of a few random frames: features that depend on the input
        for m in backbone.modules():
            if isinstance(m, nn.BatchNorm2d):
                m.momentum = None
        backbone.train()
        for _ in range(5):
            backbone.forward_features(torch.randn(8, 3, *CANVAS))   # normalised frames
    head = create_head(request.param, backbone.num_features, 13, p=0.5)
    with torch.no_grad():
        for prm in head.parameters():
            prm.mul_(2.0)  # spread the logits of a random init
    return Policy(backbone, head, policy_config(backbone, request.param, 13, input_size=CANVAS, fit="letterbox")).eval()


@pytest.fixture(scope="module")
def spec():
    return GraphSpec(size=CANVAS, mean=MEAN, std=STD, samples=1, p=0.0, fit="letterbox", pad_rgb=PAD)


@pytest.fixture(scope="module")
def pre_session(spec):
    stub = nn.Module()
    stub.head = nn.Module()                                   # preprocessing only: no weights
    module = _Pre(stub, spec).eval()
    dims = {0: torch.export.Dim("N", min=1, max=64),
            1: torch.export.Dim("H", min=8, max=MAX_SIDE), 2: torch.export.Dim("W", min=8, max=MAX_SIDE)}
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        prog = torch.onnx.export(module, (torch.zeros(2, 56, 76, 3, dtype=torch.uint8),), input_names=["frames"],
                                 output_names=["canvas", "window"], dynamic_shapes={"frames": dims},
                                 dynamo=True, external_data=False, opset_version=18, verbose=False)
    return ort.InferenceSession(prog.model_proto.SerializeToString())


def _dark_frames(h, w, n=2, seed=0):
    """Frames whose every pixel is far from the pad colour (so the content box is visible)."""
    return np.random.default_rng(seed).integers(0, 50, (n, h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize("hw", SHAPES)
def test_graph_letterbox_equals_the_geometry_arithmetic(pre_session, policy, spec, hw):
    h, w = hw
    frames = _dark_frames(h, w)
    canvas, window = pre_session.run(None, {"frames": frames})
    assert canvas.shape == (2, 3, *CANVAS)
    top, left, nh, nw = letterbox_box(h, w, CANVAS)
    pad = ((np.asarray(PAD, np.float32) / 255 - np.asarray(MEAN, np.float32)) / np.asarray(STD, np.float32))
    is_pad = np.all(np.abs(canvas - pad.reshape(1, 3, 1, 1)) < 1e-5, axis=1)     # N x H x W
    box = np.zeros(CANVAS, bool)
    box[top:top + nh, left:left + nw] = True
    for i in range(2):
        np.testing.assert_array_equal(~is_pad[i], box)       # padding exactly outside the box
    np.testing.assert_allclose(window, np.tile(content_window(h, w, CANVAS), (2, 1)), atol=1e-6)
    # and the graph's PyTorch preprocessing agrees with the exported one
    with torch.no_grad():
        x, win = BundleGraph(policy, spec).preprocess(torch.from_numpy(frames))
    np.testing.assert_allclose(canvas, x.numpy(), atol=1e-4)
    np.testing.assert_allclose(window, win.numpy(), atol=1e-6)


def test_letterbox_box_is_centred_fits_and_keeps_the_aspect():
    for h, w in SHAPES:
        top, left, nh, nw = letterbox_box(h, w, CANVAS)
        assert (nh == CANVAS[0]) or (nw == CANVAS[1])          # touches two sides
        assert 0 <= top and 0 <= left and top + nh <= CANVAS[0] and left + nw <= CANVAS[1]
        assert abs((CANVAS[0] - nh) - 2 * top) <= 1 and abs((CANVAS[1] - nw) - 2 * left) <= 1
        assert abs(nw / nh - w / h) <= (w / h) * (1.0 / min(nh, nw)) + 1e-9 or min(nh, nw) == 1
    assert letterbox_box(120, 160, CANVAS) == (0, 0, 48, 64)
    assert letterbox_box(160, 120, CANVAS) == (0, 14, 48, 36)   # 3:4 portrait: 36 px wide, centred
    assert content_window(160, 120, CANVAS) == (14 / 64, 50 / 64)
    assert content_window(160, 120, CANVAS, fit="stretch") == (0.0, 1.0)


def test_stretch_graph_fills_the_canvas(policy):
    spec = GraphSpec(size=CANVAS, mean=MEAN, std=STD, samples=1, p=0.0, fit="stretch")
    with torch.no_grad():
        x, win = BundleGraph(policy, spec).preprocess(torch.from_numpy(_dark_frames(160, 90)))
    pad = ((np.asarray(PAD) / 255 - np.asarray(MEAN)) / np.asarray(STD)).reshape(1, 3, 1, 1)
    assert not np.any(np.all(np.abs(x.numpy() - pad) < 1e-5, axis=1))
    np.testing.assert_allclose(win.numpy(), [[0.0, 1.0]] * 2)


def test_onnx_matches_pytorch_on_portrait_frames(policy, spec):
    sess = ort.InferenceSession(model_bytes(export_graph(policy, spec)))
    rng = np.random.default_rng(3)
    for h, w in [(160, 120), (160, 90), (112, 16), (120, 160)]:
        frames = rng.integers(0, 256, (2, h, w, 3), dtype=np.uint8)
        frames[:, :, : w // 2] //= 4    # a dark left half: the columns differ
        got = sess.run(["probs"], {"frames": frames})[0]
        with torch.no_grad():
            want = BundleGraph(policy, spec)(torch.from_numpy(frames))[0].numpy()
        np.testing.assert_allclose(got, want, atol=2e-4)
        # the window reaches the head: the same canvas read over the whole width differs
        with torch.no_grad():
            x, win = BundleGraph(policy, spec).preprocess(torch.from_numpy(frames))
            whole = policy(x, samples=1, mc=False)[0].softmax(-1).numpy()
        if w != 160:
            assert np.abs(whole - want).max() > 1e-3


def test_exporter_parity_check_passes_on_portrait_frames(policy, spec):
    frames = np.random.default_rng(4).integers(0, 256, (2, 160, 90, 3), dtype=np.uint8)
    assert parity_check(policy, spec, frames) < 2e-4


# ----------------------------------------------------------------------------- strip_scores

def _head_with_identity_score(width=8):
    torch.manual_seed(0)
    head = create_head("spatial", 16, 13, p=0.5)
    head = type(head)(16, 13, p=0.5, width=width)
    with torch.no_grad():
        head.score.weight.zero_()
        head.score.weight[0, 0, 0] = 1.0          # column score = channel 0 of z
        head.score.bias.zero_()
        head.bias.zero_()
    return head


def test_strip_scores_without_window_is_the_old_bilinear_resize():
    head = _head_with_identity_score()
    torch.manual_seed(1)
    for w in (3, 7, 12, 20):
        z = torch.randn(4, 8, w)
        old = F.interpolate(head.score(z).unsqueeze(2), size=(1, N_BINS), mode="bilinear",
                            align_corners=False).flatten(1) + head.bias
        torch.testing.assert_close(head.strip_scores(z), old, atol=1e-5, rtol=1e-5)
        full = torch.tensor([[0.0, 1.0]]).expand(4, 2)
        torch.testing.assert_close(head.strip_scores(z, full), old, atol=1e-5, rtol=1e-5)


def _bump(centre: float, w: int = 64) -> torch.Tensor:
    """z (1 x 8 x w) whose channel 0 peaks at column coordinate ``centre`` (a broad bump)."""
    z = torch.zeros(1, 8, w)
    z[0, 0] = torch.exp(-((torch.arange(w, dtype=torch.float32) - centre) / 2.0) ** 2) * 5.0
    return z


@pytest.mark.parametrize("window", [(0.25, 0.75), (14 / 64, 50 / 64), (0.0, 0.5)])
def test_strip_scores_map_a_column_peak_to_the_frame_strip(window):
    head = _head_with_identity_score()
    w = 64                                        # feature columns across the canvas
    x0, x1 = window
    for strip in (1, 4, 7, 12):
        frame_x = (strip - 0.5) / N_BINS          # the strip's centre in the frame
        z = _bump((x0 + (x1 - x0) * frame_x) * w - 0.5)   # the canvas column there
        s = head.strip_scores(z, torch.tensor([window]))
        assert int(s.argmax()) + 1 == strip, (window, strip, s)
        # read over the whole canvas, the same peak lands on the canvas strip instead
        s_whole = head.strip_scores(z)
        assert int(s_whole.argmax()) + 1 == min(12, int((x0 + (x1 - x0) * frame_x) * 12) + 1)


def test_window_is_per_frame():
    head = _head_with_identity_score()
    z = torch.cat([_bump(20.0), _bump(20.0)])
    win = torch.tensor([[0.0, 1.0], [14 / 64, 50 / 64]])
    s = head.strip_scores(z, win)
    # column 20 = canvas x 20.5/64 -> strip 4 of the canvas; frame x (20.5 - 14) / 36 -> strip 3
    assert int(s[0].argmax()) + 1 == 4 and int(s[1].argmax()) + 1 == 3
