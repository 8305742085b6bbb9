"""Heads: export-ready MC dropout (explicit masks), sample folding, shapes."""

import pytest
import torch
from torch import nn

from crossing_assist.models.heads import HEAD_KINDS, HeadError, create_head, mc_dropout


@pytest.mark.parametrize("kind", HEAD_KINDS)
def test_no_nn_dropout_anywhere(kind):
    head = create_head(kind, 16, 13)
    assert not any(isinstance(m, nn.modules.dropout._DropoutNd) for m in head.modules())


@pytest.mark.parametrize("kind", HEAD_KINDS)
def test_mc_samples_differ_in_mc_mode_and_match_otherwise(kind):
    torch.manual_seed(0)
    head = create_head(kind, 16, 13, p=0.5).eval()
    feats = torch.rand(3, 16, 7, 7)
    det = head(feats, samples=5, mc=False)
    assert det.shape == (5, 3, 13)
    assert torch.equal(det, det[:1].expand_as(det))
    mc = head(feats, samples=5, mc=True)
    assert mc.shape == (5, 3, 13)
    # 5 samples of >= 32 dropped units each: all equal only if every mask agrees (chance < 2^-100)
    assert not torch.allclose(mc[0], mc[1])
    # mc=None follows the mode
    assert torch.allclose(head(feats, samples=2), det[:2], atol=1e-6)
    head.train()
    assert not torch.allclose(*head(feats, samples=2))


@pytest.mark.parametrize("kind", HEAD_KINDS)
def test_samples_are_folded_after_the_trunk(kind, monkeypatch):
    head = create_head(kind, 8, 4).eval()
    calls = []
    trunk = head.trunk
    monkeypatch.setattr(head, "trunk", lambda f: calls.append(f.shape[0]) or trunk(f))
    head(torch.rand(2, 8, 7, 7), samples=16, mc=True)
    assert calls == [2]


def test_p_is_settable_and_zero_p_is_deterministic():
    head = create_head("spatial", 8, 13, p=0.5)
    head.p = 0.0
    out = head(torch.rand(2, 8, 7, 7), samples=3, mc=True)
    assert torch.allclose(out[0], out[2], atol=1e-6)


def test_mc_dropout_keeps_the_mean():
    torch.manual_seed(1)
    x = torch.ones(200_000)
    y = mc_dropout(x, 0.5, True)
    assert set(torch.unique(y).tolist()) == {0.0, 2.0}
    assert abs(float(y.mean()) - 1.0) < 0.02   # sd 0.0022: a 9-sigma margin
    assert torch.equal(mc_dropout(x, 0.5, False), x)


def test_spatial_head_works_for_any_feature_width():
    head = create_head("spatial_mlp", 8, 8).eval()
    for w in (7, 10, 14):
        assert head(torch.rand(2, 8, 7, w), mc=False).shape == (1, 2, 8)
    assert head.column_maps(torch.rand(2, 8, 7, 10)).shape == (2, 8, 12)


def test_bad_head_arguments():
    with pytest.raises(HeadError, match="valid:"):
        create_head("global", 8, 13)
    with pytest.raises(HeadError, match="dropout p"):
        create_head("spatial", 8, 13, p=1.0)


def test_spatial_head_is_translation_aware_and_groups_strips():
    """Moving the evidence to another column moves the predicted strip; 4/8-action logits are
    the log-sum-exp of their strips' scores."""
    torch.manual_seed(0)
    head = create_head("spatial", 4, 13, p=0.0).eval()
    with torch.no_grad():
        head.reduce.weight.zero_(); head.reduce.bias.zero_(); head.reduce.weight[0, 0, 0] = 1.0
        head.context.weight.zero_(); head.context.bias.zero_(); head.context.weight[0, 0, 1] = 1.0
        head.score.weight.zero_(); head.score.weight[0, 0, 0] = 5.0
    feats = torch.zeros(2, 4, 7, 12)
    feats[0, 0, :, 1] = 1.0    # evidence in column 1 (strip 2)
    feats[1, 0, :, 9] = 1.0    # column 9 (strip 10)
    assert head(feats, mc=False)[0].argmax(-1).tolist() == [2, 10]
    h4 = create_head("spatial", 4, 4, p=0.0).eval()
    h4.load_state_dict({k: v for k, v in head.state_dict().items() if not k.startswith("unknown")} |
                       {k: v for k, v in h4.state_dict().items() if k.startswith("unknown")})
    strips = head.strip_scores(head.trunk(feats))
    assert torch.allclose(h4(feats, mc=False)[0][:, 1], torch.logsumexp(strips[:, 0:4], -1), atol=1e-5)



def test_strip_spatial_head_can_peak_on_any_strip_of_a_narrow_window():
    """On a window 4 feature columns wide (a 3:4 portrait frame on a landscape canvas),
    ``spatial``'s strip scores are linear between columns, so its argmax never lands on some
    strips; ``spatial_strips`` resamples features before its non-linearity and reaches all 12."""
    torch.manual_seed(0)
    feats = torch.randn(400, 8, 2, 4) * 3
    reached = {}
    for kind in ("spatial", "spatial_strips"):
        head = create_head(kind, 8, 13, p=0.0).eval()
        with torch.no_grad():
            for prm in head.parameters():
                prm.mul_(4.0)
            maps = head.column_maps(feats)[:, 0]                          # N x 12
        reached[kind] = set((maps.argmax(1) + 1).tolist())
    assert len(reached["spatial"]) <= 6
    assert reached["spatial_strips"] == set(range(1, 13))
    head = create_head("spatial_strips", 8, 13, p=0.5).eval()
    z = head.trunk(feats[:2])
    assert z.shape == (2, 128, 4)
    whole = head.tail(z, mc=False)
    portrait = head.tail(z, mc=False, window=torch.tensor([[0.21875, 0.78125]] * 2))
    assert whole.shape == portrait.shape == (2, 13) and not torch.allclose(whole, portrait)
    assert not torch.allclose(head(feats[:2], samples=2, mc=True)[0], head(feats[:2], samples=2, mc=True)[1])


def test_fine_spatial_head_scores_twice_the_columns_and_reads_the_window():
    """spatial_fine: the trunk has 2w columns (so its scores can peak between two feature
    columns); a narrower window (a portrait frame on a landscape canvas) reads other strips."""
    torch.manual_seed(0)
    head = create_head("spatial_fine", 8, 13, p=0.0).eval()
    feats = torch.rand(2, 8, 3, 7)
    assert head.trunk(feats).shape == (2, 128, 14)
    whole = head.tail(head.trunk(feats), mc=False)
    portrait = head.tail(head.trunk(feats), mc=False, window=torch.tensor([[0.21875, 0.78125]] * 2))
    assert whole.shape == portrait.shape == (2, 13) and not torch.allclose(whole, portrait)
