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
    assert torch.equal(out[0], out[2])


def test_mc_dropout_keeps_the_mean():
    torch.manual_seed(1)
    x = torch.ones(200_000)
    y = mc_dropout(x, 0.5, True)
    assert set(torch.unique(y).tolist()) == {0.0, 2.0}
    assert abs(float(y.mean()) - 1.0) < 0.02   # sd 0.0022: a 9-sigma margin
    assert torch.equal(mc_dropout(x, 0.5, False), x)


def test_spatial_head_works_for_any_feature_width():
    head = create_head("spatial", 8, 8).eval()
    for w in (7, 10, 14):
        assert head(torch.rand(2, 8, 7, w), mc=False).shape == (1, 2, 8)
    assert head.column_maps(torch.rand(2, 8, 7, 10)).shape == (2, 8, 12)


def test_bad_head_arguments():
    with pytest.raises(HeadError, match="valid:"):
        create_head("global", 8, 13)
    with pytest.raises(HeadError, match="dropout p"):
        create_head("spatial", 8, 13, p=1.0)
