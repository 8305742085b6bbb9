"""The one-pass MC-dropout ONNX graph, run under onnxruntime with DEFAULT session options.

Fast tests use the real ``Policy`` and heads on a tiny ``Backbone`` (BatchNorm running
statistics measured on data, not the init values); the slow test repeats the key checks on
EfficientNet-Lite0 with its shipped ImageNet weights, for every head kind.
"""

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from torch import nn

from crossing_assist.export.graph import BundleGraph, GraphSpec, export_graph, mc_summaries, model_bytes
from crossing_assist.models.backbones import Backbone, BackboneFacts, create_backbone
from crossing_assist.models.heads import HEAD_KINDS, create_head
from crossing_assist.models.policy import Policy, policy_config

MEAN, STD = (0.485, 0.456, 0.406), (0.229, 0.224, 0.225)


def tiny_policy(kind: str = "spatial", n_actions: int = 13, seed: int = 0) -> Policy:
    torch.manual_seed(seed)
    blocks = [
        nn.Sequential(nn.Conv2d(3, 8, 3, stride=2, padding=1), nn.BatchNorm2d(8, momentum=None), nn.ReLU()),
        nn.Sequential(nn.Conv2d(8, 16, 3, stride=2, padding=1), nn.BatchNorm2d(16, momentum=None), nn.ReLU()),
    ]
    facts = BackboneFacts("tiny", (32, 32), MEAN, STD, "none", "test")
    backbone = Backbone(blocks, 16, facts)
    # Measure real BatchNorm statistics (cumulative average) on structured images.
    rng = np.random.default_rng(seed)
    backbone.train()
    with torch.no_grad():
        for _ in range(4):
            x = torch.from_numpy(rng.normal(0, 1, (16, 3, 32, 32)).astype(np.float32)).cumsum(-1) / 4
            backbone(x)
    policy = Policy(backbone, create_head(kind, 16, n_actions, p=0.5),
                    policy_config(backbone, kind, n_actions, input_size=(32, 32))).eval()
    with torch.no_grad():  # make the logits spread out so that dropout visibly changes them
        for prm in policy.head.parameters():
            prm.mul_(3.0)
    return policy


def frames(n=3, h=40, w=48, seed=1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (n, 1, w, 3))
    return np.clip(base + rng.integers(-30, 30, (n, h, w, 3)), 0, 255).astype(np.uint8)


def session(policy, spec) -> ort.InferenceSession:
    return ort.InferenceSession(model_bytes(export_graph(policy, spec)))  # default options


@pytest.fixture(scope="module")
def policy():
    return tiny_policy()


@pytest.fixture(scope="module")
def mc_spec(policy):
    return GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=16, p=0.5, temperature=1.5)


@pytest.fixture(scope="module")
def mc_session(policy, mc_spec):
    return session(policy, mc_spec)


def run(sess, x):
    return dict(zip([o.name for o in sess.get_outputs()], sess.run(None, {"frames": x})))


def test_graph_is_one_file_with_random_op_and_dynamic_input(policy, mc_spec):
    model = export_graph(policy, mc_spec)
    ops = [n.op_type for n in model.graph.node]
    assert "RandomUniformLike" in ops and "Dropout" not in ops
    assert all(i.data_location != onnx.TensorProto.EXTERNAL for i in model.graph.initializer)
    n_params = sum(p.numel() for p in policy.parameters())
    assert len(model_bytes(model)) > 4 * n_params  # weights embedded
    (inp,) = model.graph.input
    dims = [d.dim_param or d.dim_value for d in inp.type.tensor_type.shape.dim]
    assert inp.type.tensor_type.elem_type == onnx.TensorProto.UINT8
    assert isinstance(dims[0], str) and isinstance(dims[1], str) and isinstance(dims[2], str) and dims[3] == 3


def test_dropout_stays_random_under_default_options(mc_session):
    x = frames()
    a, b = run(mc_session, x), run(mc_session, x)
    assert np.abs(a["probs"] - b["probs"]).max() > 1e-4, "two runs on the same frame gave the same output"
    assert (a["variance"].max(axis=1) > 1e-6).all()
    assert (a["mutual_info"] > 0).all()


def test_outputs_are_consistent(mc_session, mc_spec):
    x = frames(n=4, h=33, w=70)
    out = run(mc_session, x)
    p = out["probs"]
    assert p.shape == (4, 13) and out["variance"].shape == (4, 13) and out["entropy"].shape == (4,)
    np.testing.assert_allclose(p.sum(1), 1, atol=1e-5)
    np.testing.assert_allclose(out["entropy"], -(p * np.log(p)).sum(1), atol=1e-5)
    assert ((out["mutual_info"] >= 0) & (out["mutual_info"] <= out["entropy"] + 1e-6)).all()
    np.testing.assert_allclose(out["votes"].sum(1), 1, atol=1e-6)
    np.testing.assert_allclose(out["votes"] * mc_spec.samples, np.round(out["votes"] * mc_spec.samples), atol=1e-4)


def test_mean_probs_match_pytorch_mc_expectation(policy, mc_spec, mc_session):
    """ORT's mean probabilities over R=100 runs (1,600 samples a frame) against PyTorch's over
    K=8,000 samples. Tolerance 6 standard errors of the difference (per-sample std measured
    from the PyTorch samples) + 1e-6: by the CLT a false failure has probability about 2e-9 per
    entry, < 1e-7 over the 39 entries."""
    x = frames()
    k = 8000
    graph = BundleGraph(policy, GraphSpec(**{**mc_spec.__dict__, "samples": k}))
    with torch.no_grad():
        logits = graph.logits(torch.from_numpy(x))
        p_s = torch.softmax(logits / mc_spec.temperature, -1).numpy()  # K x N x A
    expect, sd = p_s.mean(0), p_s.std(0)
    r = 100
    got = np.mean([run(mc_session, x)["probs"] for _ in range(r)], axis=0)
    tol = 6 * sd * np.sqrt(1 / (r * mc_spec.samples) + 1 / k) + 1e-6
    assert sd.max() > 1e-3, "the test model's samples barely vary; the check would be vacuous"
    assert (np.abs(got - expect) <= tol).all(), f"max excess {np.max(np.abs(got - expect) - tol)}"


@pytest.mark.parametrize("hw", [(32, 32), (40, 48), (20, 24), (97, 31)])
def test_deterministic_path_matches_pytorch(policy, hw):
    spec = GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=1, p=0.0, temperature=2.5)
    sess = _det_session(policy, spec)
    x = frames(n=2, h=hw[0], w=hw[1])
    out = run(sess, x)
    with torch.no_grad():
        ref = [t.numpy() for t in BundleGraph(policy, spec)(torch.from_numpy(x))]
        logits = BundleGraph(policy, spec).logits(torch.from_numpy(x))[0]
    for name, want in zip(["probs", "entropy", "mutual_info", "variance", "votes"], ref):
        np.testing.assert_allclose(out[name], want, atol=1e-4, err_msg=name)
    np.testing.assert_allclose(out["probs"], torch.softmax(logits / 2.5, -1).numpy(), atol=1e-4)
    assert (out["variance"] == 0).all() and np.allclose(out["mutual_info"], 0, atol=1e-6)


_DET: dict = {}


def _det_session(policy, spec):
    if spec not in _DET:
        _DET[spec] = session(policy, spec)
    return _DET[spec]


def test_mc_summaries_on_known_samples():
    logits = torch.log(torch.tensor([[[0.9, 0.1]], [[0.1, 0.9]]]))  # two samples disagree
    probs, ent, mi, var, votes = mc_summaries(logits)
    np.testing.assert_allclose(probs.numpy(), [[0.5, 0.5]], atol=1e-6)
    np.testing.assert_allclose(ent.numpy(), [np.log(2)], atol=1e-6)
    h_sample = -(0.9 * np.log(0.9) + 0.1 * np.log(0.1))
    np.testing.assert_allclose(mi.numpy(), [np.log(2) - h_sample], atol=1e-6)
    np.testing.assert_allclose(var.numpy(), [[0.16, 0.16]], atol=1e-6)
    np.testing.assert_allclose(votes.numpy(), [[0.5, 0.5]])


def test_graph_refuses_head_without_random_masks():
    class NoMc(nn.Module):
        def __init__(self):
            super().__init__()
            self.head = nn.Linear(3, 4)
            self.head.p = 0.5

        def forward(self, x, samples=1, mc=None, window=None):
            return self.head(x.mean((2, 3))).unsqueeze(0).expand(samples, -1, -1)

    with pytest.raises(RuntimeError, match="no random op"):
        export_graph(NoMc(), GraphSpec(size=(16, 16), mean=MEAN, std=STD, samples=4, p=0.5))


@pytest.mark.slow
@pytest.mark.parametrize("kind", HEAD_KINDS)
def test_real_pretrained_backbone_keeps_dropout_random(kind):
    """EfficientNet-Lite0 with its shipped ImageNet weights (real BatchNorm statistics)."""
    torch.manual_seed(0)
    backbone = create_backbone("efficientnet_lite0", weights="imagenet")
    policy = Policy(backbone, create_head(kind, backbone.num_features, 13, p=0.5),
                    policy_config(backbone, kind, 13, input_size=(96, 96))).eval()
    spec = GraphSpec(size=(96, 96), mean=backbone.facts.mean, std=backbone.facts.std, samples=16, p=0.5)
    sess = session(policy, spec)
    x = frames(n=2, h=120, w=160)
    a, b = run(sess, x), run(sess, x)
    assert np.abs(a["probs"] - b["probs"]).max() > 1e-6
    assert (a["variance"].max(1) > 0).all()
    det = GraphSpec(size=(96, 96), mean=backbone.facts.mean, std=backbone.facts.std, samples=1, p=0.0)
    out = run(session(policy, det), x)
    with torch.no_grad():
        want = BundleGraph(policy, det)(torch.from_numpy(x))[0].numpy()
    np.testing.assert_allclose(out["probs"], want, atol=1e-4)


@pytest.mark.parametrize("kind", HEAD_KINDS)
def test_every_head_runs_batches_of_any_size_in_the_graph(kind):
    """The graph takes any number of frames: a head whose export hard-codes the traced batch (an
    ONNX Resize given output sizes) would fail on 1 or 3 frames in onnxruntime."""
    policy = tiny_policy(kind)
    spec = GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=1, p=0.0)
    sess = session(policy, spec)
    for n in (1, 3):
        x = frames(n=n)
        with torch.no_grad():
            want = BundleGraph(policy, spec)(torch.from_numpy(x))[0].numpy()
        np.testing.assert_allclose(run(sess, x)["probs"], want, atol=1e-4)


def test_default_head_exports_random_and_exact():
    from crossing_assist.models.config import TrainConfig

    policy = tiny_policy(TrainConfig.head, n_actions=8)
    mc = session(policy, GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=16, p=0.5))
    x = frames(n=2)
    a, b = run(mc, x), run(mc, x)
    assert a["probs"].shape == (2, 8) and np.abs(a["probs"] - b["probs"]).max() > 1e-5
    assert (a["variance"].max(1) > 0).all()
    det = GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=1, p=0.0)
    with torch.no_grad():
        want = BundleGraph(policy, det)(torch.from_numpy(x))[0].numpy()
    np.testing.assert_allclose(run(session(policy, det), x)["probs"], want, atol=1e-4)


@pytest.mark.parametrize("hw", [(36, 48), (48, 48), (48, 36)])   # padding even on both sides (else the canvas
def test_mirror_graph_averages_the_frame_and_its_mirror_image_with_actions_mapped_back(policy, hw):  # flip shifts 1 px)
    """``mirror``: the deterministic graph's probs are the mean of the plain graph's on the frame
    and on its mirror image (strip k -> 13 - k); so the mirrored frame gives the mirrored probs."""
    det = GraphSpec(size=(24, 32), mean=MEAN, std=STD, samples=1, p=0.0, fit="letterbox")
    plain, both = session(policy, det), session(policy, GraphSpec(**{**det.__dict__, "mirror": True}))
    x = frames(2, *hw)
    flipped = np.ascontiguousarray(x[:, :, ::-1])
    perm = [0] + list(range(12, 0, -1))
    want = (run(plain, x)["probs"] + run(plain, flipped)["probs"][:, perm]) / 2
    got = run(both, x)["probs"]
    np.testing.assert_allclose(got, want, atol=1e-5)
    np.testing.assert_allclose(run(both, flipped)["probs"], got[:, perm], atol=1e-5)
    assert np.abs(run(plain, x)["probs"] - got).max() > 1e-3   # the mirror really changed something


def test_mirror_graph_summarises_both_sets_of_mc_samples(policy):
    """2T samples: the votes are multiples of 1/(2T) and the outputs keep their shapes."""
    spec = GraphSpec(size=(32, 32), mean=MEAN, std=STD, samples=4, p=0.5, mirror=True)
    out = run(session(policy, spec), frames(3))
    assert out["probs"].shape == (3, 13) and out["votes"].shape == (3, 13)
    np.testing.assert_allclose(out["votes"].sum(1), 1.0, atol=1e-6)
    np.testing.assert_allclose(out["votes"] * 8, np.round(out["votes"] * 8), atol=1e-5)
    assert np.all(out["mutual_info"] >= 0) and np.all(np.isfinite(out["entropy"]))


def test_stride16_lite0_policy_exports_exactly():
    """EfficientNet-Lite0 with ``feature_stride=16`` (its stride-16 block beside the upsampled
    deepest features): the graph's deterministic probs match PyTorch at a frame of another aspect."""
    torch.manual_seed(0)
    bb = create_backbone("efficientnet_lite0", weights="none", feature_stride=16)
    head = create_head("spatial_fine", bb.num_features, 13, p=0.5)
    policy = Policy(bb, head, policy_config(bb, head.kind, 13, input_size=(48, 64), feature_stride=16)).eval()
    spec = GraphSpec(size=(48, 64), mean=MEAN, std=STD, samples=1, p=0.0, fit="letterbox")
    x = frames(n=2, h=64, w=48)
    with torch.no_grad():
        want = BundleGraph(policy, spec)(torch.from_numpy(x))[0].numpy()
    np.testing.assert_allclose(run(session(policy, spec), x)["probs"], want, atol=1e-4)
